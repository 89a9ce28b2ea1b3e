"""Re-evaluate a saved ``baselines.sb3_pose`` surface-mode checkpoint against uniform surface
actions on more held-out episodes than the training run used (issue 40, part 6): the same
seeded episodes for both, the registered ``policy`` evaluator, Wilson 95% intervals.

    .venv/bin/python bench/pose_surface_eval.py runs/sb3/surface_sac60k/sac_pose_surface.zip \
        --episodes 3000
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from baselines.sb3_common import split_objects, uniform_actions
from baselines.sb3_pose import ENV_ID
from dg16m_env.evaluators import load_benchmark_ref, make


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", type=Path, help="a SAC checkpoint written by sb3_pose")
    parser.add_argument("--episodes", type=int, default=3000, help="default: 3000")
    parser.add_argument("--seed", type=int, default=100_000, help="first episode seed")
    parser.add_argument("--n-points", type=int, default=64, help="as in training (default 64)")
    args = parser.parse_args()
    from stable_baselines3 import SAC

    model = SAC.load(args.checkpoint, device="cpu")
    _, test_ids = split_objects(load_benchmark_ref().object_ids)
    kwargs = {"n_points": args.n_points, "fc_info": False, "action_mode": "surface"}
    evaluator = make(
        "policy",
        env_id=ENV_ID,
        n_episodes=args.episodes,
        seed=args.seed,
        env_kwargs={**kwargs, "object_ids": test_ids},
        progress=True,
    )
    rates = {
        "sac": evaluator.evaluate(model).metrics["success_rate"],
        "uniform_surface_actions": evaluator.evaluate(uniform_actions((2, 3), 0)).metrics[
            "success_rate"
        ],
    }
    for name, rate in rates.items():
        print(
            f"{name:24s} {100 * rate['rate']:.2f}% [{100 * rate['ci_low']:.2f}, "
            f"{100 * rate['ci_high']:.2f}] over {rate['episodes']} episodes"
        )
    print(json.dumps(rates))


if __name__ == "__main__":
    main()
