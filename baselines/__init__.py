"""Stable-Baselines3 baselines and a model-based controller for the soft-arm environments.

* :mod:`baselines.train` — ``python -m baselines.train --env ID --algo sac --seed S``;
* :mod:`baselines.evaluate` — ``python -m baselines.evaluate --model FILE.zip --observation ...``;
* the damped-least-squares Jacobian controller lives in :mod:`softarm_gym.controllers`;
* :mod:`baselines.results` — regenerates ``baselines/RESULTS.md`` and its plots;
* ``baselines/hyperparams/<algo>.yml`` — hyperparameters per environment (zoo layout).
"""
