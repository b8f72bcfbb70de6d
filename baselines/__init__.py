"""Stable-Baselines3 baselines and a model-based controller for the soft-arm environments.

* :mod:`baselines.train` — ``python -m baselines.train --env ID --algo sac --seed S`` (``--resume
  RUN_DIR`` after an interruption; ``train()``/``resume()`` from Python);
* :mod:`baselines.sweep` — ``python -m baselines.sweep --envs ... --algos ... --seeds 0-9
  --observations ... [--backend ray]``: many trainings, here or one Ray task each, then results;
* :mod:`baselines.evaluate` — ``python -m baselines.evaluate --model FILE.zip --observation ...``;
* the damped-least-squares Jacobian controller lives in :mod:`softarm_gym.controllers`;
* :mod:`baselines.results` — regenerates ``baselines/RESULTS.md`` and its plots;
* :mod:`baselines.convert` — turns a trusted model with pickled sidecars into the safe format;
* :mod:`baselines.faults` — a drill that interrupts and resumes a training run;
* ``baselines/hyperparams/<algo>.yml`` — hyperparameters per environment (zoo layout).
"""
