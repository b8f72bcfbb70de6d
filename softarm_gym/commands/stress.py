"""``softarm stress``: the numerical-stability stress study (random and adversarial scenes, env steps)."""

from __future__ import annotations

from softarm_gym.cli import UsageError
from softarm_gym.commands.common import add_quiet_argument
from softarm_gym.commands.long_jobs import (
    add_job_arguments,
    check_outputs,
    finish,
    interruptible,
    runner_from_args,
)

NAME = "stress"
HELP = "stress-test the solver and environments (random and adversarial scenes, random actions)"


def add_arguments(p):
    p.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    p.add_argument("--n-random", type=int, default=5000,
                   help="solves in the random set (default %(default)s)")
    p.add_argument("--n-per-class", type=int, default=200,
                   help="trials per adversarial class (default %(default)s; a wrap_press trial is an "
                        "8-step ramp)")
    p.add_argument("--classes", default=None,
                   help="comma-separated adversarial classes (default: all)")
    p.add_argument("--env-steps", type=int, default=100_000,
                   help="random-action environment steps over all IDs and observation modes "
                        "(default %(default)s; 0 skips them)")
    p.add_argument("--observations", default=None, metavar="OBS[,OBS]",
                   help="estimators the environment steps use (default: all of them)")
    p.add_argument("--diagnose", type=int, default=20,
                   help="failed solves per class retried with stronger settings (default %(default)s)")
    p.add_argument("--quick", action="store_true",
                   help="smoke run: 200 random solves, 10 per class, 480 env steps")
    add_quiet_argument(p, help="no progress bars on stderr")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_job_arguments(p, "trials per chunk (default: about 1 s of solves); an env case is one chunk")


@interruptible
def run(args) -> int:
    from softarm_gym.benchmarks import stress

    n_random, n_per_class, env_steps = args.n_random, args.n_per_class, args.env_steps
    if args.quick:
        n_random, n_per_class, env_steps = 200, 10, 480
    for flag, value in (("--n-random", n_random), ("--n-per-class", n_per_class),
                        ("--env-steps", env_steps), ("--diagnose", args.diagnose)):
        if value < 0:
            raise UsageError(f"{flag} must be >= 0; got {value}")
    classes = None
    if args.classes is not None:
        classes = tuple(c.strip() for c in args.classes.split(",") if c.strip())
        unknown = [c for c in classes if c not in stress.CLASSES]
        if unknown or not classes:
            raise UsageError(f"unknown stress class {', '.join(unknown) or repr(args.classes)}; "
                             f"choose from {', '.join(stress.CLASSES)}")
    check_outputs(args)
    runner = runner_from_args(args, progress=not args.quiet)
    observations = None if args.observations is None else tuple(
        o.strip() for o in args.observations.split(",") if o.strip())
    try:
        study = stress.plan(seed=args.seed, n_random=n_random, n_per_class=n_per_class,
                            env_steps=env_steps, classes=classes, n_diagnose=args.diagnose,
                            chunk_size=args.chunk_size or stress.DEFAULT_STRESS_CHUNK,
                            observations=observations)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    (result,) = runner.run_plans([study], desc="stress", unit="solve")
    finish(args, result, stress.format_report(result), runner)
    return 0 if result["targets"]["zero_nan"] else 1
