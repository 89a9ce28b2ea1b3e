"""The ``policy`` evaluator on a tiny guessing environment registered here."""

from __future__ import annotations

import json
from typing import Any

import gymnasium
import numpy as np
import pytest
from gymnasium import spaces

from dataset_gen.io import package_version
from dg16m_env.evaluators.policy import PolicyEvaluator, wilson_interval
from dg16m_env.evaluators.registry import EvaluatorError, make
from dg16m_env.evaluators.result import EvaluationResult

ENV_ID = "dg16m_test/Guess-v0"


class GuessEnv(gymnasium.Env):
    """One step: the observation shows a hidden bit; success when the action names it.

    Args:
        success_key: the info key of the verdict (None: no verdict at all).
        continuous: a Box(-1, 1, (1,)) action whose sign names the bit (> 0: 1).
        steps: steps per episode (the verdict comes on the last one).
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 (gymnasium's convention)

    def __init__(
        self, success_key: str | None = "success", continuous: bool = False, steps: int = 1
    ) -> None:
        self.observation_space = spaces.Box(0.0, 1.0, (1,), np.float32)
        self.action_space = (
            spaces.Box(-1.0, 1.0, (1,), np.float32) if continuous else spaces.Discrete(2)
        )
        self.success_key, self.continuous, self.steps = success_key, continuous, steps
        self.bit, self.t = 0, 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.bit, self.t = int(self.np_random.integers(2)), 0
        return np.array([self.bit], np.float32), {"object_id": f"bit{self.bit}"}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        guess = int(np.asarray(action).reshape(-1)[0] > 0) if self.continuous else int(action)
        self.t += 1
        done = self.t >= self.steps
        success = guess == self.bit
        info = {self.success_key: success} if done and self.success_key else {}
        return np.array([self.bit], np.float32), float(success), done, False, info


if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point=GuessEnv, max_episode_steps=10)


def bits(n: int, seed: int = 0) -> np.ndarray:
    """The hidden bit of each episode, as the evaluator's resets draw them."""
    env = GuessEnv()
    return np.array([env.reset(seed=seed + i)[0][0] for i in range(n)], dtype=int)


def oracle(observation: np.ndarray) -> int:
    return int(observation[0] > 0.5)


def constant(observation: np.ndarray) -> int:
    return 0


def test_wilson_interval_by_hand() -> None:
    half = wilson_interval(50, 100)
    assert half["rate"] == 0.5
    assert half["ci_low"] == pytest.approx(0.403832, abs=1e-6)
    assert half["ci_high"] == pytest.approx(0.596168, abs=1e-6)
    assert wilson_interval(0, 10)["ci_low"] == 0.0
    assert wilson_interval(10, 10)["ci_high"] == 1.0
    assert wilson_interval(10, 10)["ci_low"] == pytest.approx(0.722467, abs=1e-6)
    assert wilson_interval(0, 0)["rate"] is None
    with pytest.raises(EvaluatorError, match="expected at most n = 3"):
        wilson_interval(4, 3)


def test_oracle_succeeds_every_time() -> None:
    result = make("policy", env_id=ENV_ID).evaluate(oracle)
    rate = result.metrics["success_rate"]
    assert rate["rate"] == 1.0
    assert rate["ci_high"] == 1.0
    assert rate["rows"] == rate["episodes"] == 100
    assert result.metrics["mean_return"] == 1.0
    assert result.metrics["mean_length"] == 1.0
    assert result.score == 1.0
    assert not result.details["failure_reasons"]


def test_constant_policy_is_a_coin_flip() -> None:
    # Seed 100: seed 0 happens to draw 61 ones in 100 episodes, outside the interval as about
    # 5 % of seeds do (the coverage over many seeds is checked below).
    result = make("policy", env_id=ENV_ID, n_episodes=100, seed=100).evaluate(constant)
    rate = result.metrics["success_rate"]
    assert rate["rate"] == pytest.approx(float(np.mean(bits(100, seed=100) == 0)))
    assert rate["ci_low"] < 0.5 < rate["ci_high"]
    assert rate["objects"] == 2
    assert result.per_object["bit0"]["success_rate"]["rate"] == 1.0
    assert result.per_object["bit1"]["success_rate"]["rate"] == 0.0
    assert result.per_object["bit0"]["episodes"] + result.per_object["bit1"]["episodes"] == 100
    assert "(100 rows, 2 objects)" in result.format()


def test_wilson_interval_covers_a_fair_coin() -> None:
    runs = [
        make("policy", env_id=ENV_ID, n_episodes=100, seed=100 * b).evaluate(constant)
        for b in range(40)
    ]
    rates = [r.metrics["success_rate"] for r in runs]
    covered = sum(r["ci_low"] < 0.5 < r["ci_high"] for r in rates)
    assert covered >= 34  # 95 % nominal: 38 expected; 36 with these seeds
    assert np.mean([r["rate"] for r in rates]) == pytest.approx(0.5, abs=0.02)


def test_same_seed_same_result_other_seed_other_episodes() -> None:
    first = make("policy", env_id=ENV_ID, n_episodes=40, seed=7).evaluate(constant)
    second = make("policy", env_id=ENV_ID, n_episodes=40, seed=7).evaluate(constant)
    assert first.to_dict() == second.to_dict()
    other = make("policy", env_id=ENV_ID, n_episodes=40, seed=8).evaluate(constant)
    assert other.metrics["success_rate"]["rate"] == pytest.approx(np.mean(bits(40, 8) == 0))
    text = json.dumps(first.to_dict(), allow_nan=False)
    assert EvaluationResult.from_dict(json.loads(text)).to_dict() == first.to_dict()


def test_result_records_the_run() -> None:
    ev = make(
        "policy", env_id=ENV_ID, n_episodes=5, seed=3, env_kwargs={"steps": 2}, max_episode_steps=4
    )
    result = ev.evaluate(oracle)
    assert result.evaluator == "policy"
    assert result.evaluator_version == "1"
    assert result.package_version == package_version()
    assert result.benchmark == {}
    assert result.seeds == {"reset": 3}
    assert result.metrics["mean_length"] == 2.0
    params = result.parameters
    assert params["env_id"] == ENV_ID
    assert params["n_episodes"] == 5
    assert params["env_kwargs"] == {"steps": 2}
    assert params["env"]["entry_point"].endswith("GuessEnv")
    assert params["env"]["version"] == 0
    assert params["env"]["max_episode_steps"] == 4
    assert result.subject["kind"] == "policy"
    assert result.subject["interface"] == "callable"


def test_time_limit_truncates_long_episodes() -> None:
    ev = make("policy", env_id=ENV_ID, n_episodes=4, env_kwargs={"steps": 50})
    with pytest.raises(EvaluatorError, match=r"found keys \[\]"):
        ev.evaluate(oracle)  # truncated by the registered limit (10 steps): no verdict


def test_keyboard_interrupt_is_not_swallowed() -> None:
    def interrupted(observation: np.ndarray) -> int:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        make("policy", env_id=ENV_ID, n_episodes=2).evaluate(interrupted)


def test_policy_errors_fail_their_episodes() -> None:
    n = 30

    def picky(observation: np.ndarray) -> int:
        if observation[0] > 0.5:
            raise ValueError("cannot see")
        return 0

    result = make("policy", env_id=ENV_ID, n_episodes=n).evaluate(picky)
    ones = int(bits(n).sum())
    assert result.metrics["success_rate"]["rate"] == pytest.approx((n - ones) / n)
    assert result.metrics["success_rate"]["rows"] == n
    assert result.details["failure_reasons"] == {"ValueError: cannot see": ones}
    assert len(result.details["failed_episodes"]) == ones
    assert result.metrics["mean_length"] == pytest.approx((n - ones) / n)


@pytest.mark.parametrize("action", [2, -1, 0.0, "a", np.array([0, 1]), None])
def test_actions_outside_the_space_fail(action: Any) -> None:
    result = make("policy", env_id=ENV_ID, n_episodes=6).evaluate(lambda obs: action)
    assert result.metrics["success_rate"]["rate"] == 0.0
    assert result.details["failure_reasons"] == {"action outside Discrete(2)": 6}
    assert result.details["failed_episodes"]["0"].startswith(
        "action: expected an element of Discrete(2), found"
    )


@pytest.mark.parametrize("kind", [int, np.int64, np.int32, np.array])
def test_discrete_accepts_numpy_integers(kind: Any) -> None:
    result = make("policy", env_id=ENV_ID, n_episodes=10).evaluate(lambda obs: kind(oracle(obs)))
    assert result.metrics["success_rate"]["rate"] == 1.0


def test_box_actions() -> None:
    def signed(obs: np.ndarray) -> list[float]:
        return [0.5 if obs[0] > 0.5 else -0.5]  # float64 list for a float32 Box

    ev = make("policy", env_id=ENV_ID, n_episodes=10, env_kwargs={"continuous": True})
    assert ev.evaluate(signed).metrics["success_rate"]["rate"] == 1.0
    for bad in ([2.0], [np.nan], [[0.5]], 0.5):
        result = ev.evaluate(lambda obs, bad=bad: bad)
        assert result.metrics["success_rate"]["rate"] == 0.0
        assert list(result.details["failure_reasons"]) == [
            "action outside Box(-1.0, 1.0, (1,), float32)"
        ]


def test_env_without_success_keys_is_refused() -> None:
    ev = make("policy", env_id=ENV_ID, n_episodes=3, env_kwargs={"success_key": None})
    with pytest.raises(EvaluatorError, match=r"expected info\['success'\] or info\['is_success'\]"):
        ev.evaluate(oracle)
    with pytest.raises(EvaluatorError, match=r"env CartPole-v1: expected info\['success'\]"):
        make("policy", env_id="CartPole-v1", n_episodes=1).evaluate(lambda obs: 0)
    by_module = make("policy", env_id="gymnasium.envs.classic_control:CartPole-v1", n_episodes=1)
    assert by_module.spec.id == "CartPole-v1"
    with pytest.raises(EvaluatorError, match=r"expected info\['success'\]"):
        by_module.evaluate(lambda obs: 0)


def test_is_success_key_is_read() -> None:
    ev = make("policy", env_id=ENV_ID, n_episodes=10, env_kwargs={"success_key": "is_success"})
    assert ev.evaluate(oracle).metrics["success_rate"]["rate"] == 1.0


class FakeModel:
    """An object with a stable-baselines3-style ``predict``."""

    name = "fake"

    def predict(self, observation: np.ndarray, deterministic: bool = False) -> tuple[Any, None]:
        guess = oracle(observation) if deterministic else 0
        return np.array(guess), None


def test_predict_objects_get_the_deterministic_flag() -> None:
    sharp = make("policy", env_id=ENV_ID, n_episodes=20).evaluate(FakeModel())
    assert sharp.metrics["success_rate"]["rate"] == 1.0
    assert sharp.subject["name"] == "fake"
    assert sharp.subject["interface"] == "predict"
    loose = make("policy", env_id=ENV_ID, n_episodes=20, deterministic=False).evaluate(FakeModel())
    assert loose.metrics["success_rate"]["rate"] == pytest.approx(np.mean(bits(20) == 0))
    assert loose.parameters["deterministic"] is False


def test_untrained_stable_baselines3_model_runs() -> None:
    sb3 = pytest.importorskip("stable_baselines3")
    model = sb3.PPO("MlpPolicy", gymnasium.make(ENV_ID), seed=0, device="cpu")
    result = make("policy", env_id=ENV_ID, n_episodes=10).evaluate(model)
    assert 0.0 <= result.metrics["success_rate"]["rate"] <= 1.0
    assert not result.details["failure_reasons"]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"env_id": "dg16m_test/Nope-v0"}, "expected a registered Gymnasium id"),
        ({"env_id": "no_such_module_xyz:Guess-v0"}, "expected a registered Gymnasium id"),
        ({}, "env_id: expected a registered Gymnasium id"),
        ({"env_id": ENV_ID, "n_episodes": 0}, "n_episodes: expected an integer >= 1"),
        ({"env_id": ENV_ID, "env_kwargs": [1]}, "env_kwargs: expected a mapping"),
        ({"env_id": ENV_ID, "bad_arg": 1}, "found unknown ['bad_arg']"),
    ],
)
def test_bad_arguments(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(EvaluatorError) as info:
        make("policy", **kwargs)
    assert message in str(info.value)
    if "Nope" in str(kwargs.get("env_id")):
        assert "gymnasium.pprint_registry()" in str(info.value)


def test_env_that_cannot_be_made() -> None:
    ev = make("policy", env_id=ENV_ID, env_kwargs={"colour": "red"})
    with pytest.raises(EvaluatorError, match=r"expected gymnasium\.make to succeed"):
        ev.evaluate(oracle)


def test_not_a_policy() -> None:
    ev = make("policy", env_id=ENV_ID)
    assert isinstance(ev, PolicyEvaluator)
    with pytest.raises(EvaluatorError, match=r"expected a callable policy.* found builtins.int"):
        ev.evaluate(5)


def test_a_stateful_policy_is_reset_at_every_episode() -> None:
    class Counting:
        def __init__(self) -> None:
            self.resets = 0
            self.calls = 0

        def reset(self) -> None:
            self.resets += 1

        def __call__(self, observation: Any) -> int:
            self.calls += 1
            return 0

    policy = Counting()
    make("policy", env_id=ENV_ID, n_episodes=7, seed=0).evaluate(policy)
    assert policy.resets == 7
    assert policy.calls >= 7
