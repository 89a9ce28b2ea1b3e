"""Which physics engine runs the trials: C MuJoCo (the default) or MuJoCo Warp (optional extra).

Both run the same compiled scene (:func:`dg16m_env.physics.scene.compile_scene`), the same
:class:`~dg16m_env.physics.trial.TrialProtocol` and the same judge (:func:`dg16m_env.physics.trial.judge`); only
the stepping differs:

* ``"mujoco"``: C MuJoCo in float64 through ``mujoco.rollout``, one core per process, batches of
  :attr:`~dg16m_env.physics.trial.TrialProtocol.batch_size` trials. Bit-for-bit reproducible on one
  machine. The reference: the shipped benchmark's labels come from it.
* ``"warp"``: MuJoCo Warp (``pip install 'dg16m[warp]'``) in float32, up to :attr:`Simulator.worlds`
  trials of one object stepped together as Warp worlds on a CUDA GPU (or, for checking, on
  Warp's CPU device). Its labels agree with the CPU path's statistically, not bit for bit (float32,
  and on a GPU, atomics: see :attr:`Simulator.deterministic` and BENCHMARKS.md for the measured
  agreement). :mod:`dg16m_env.physics.warp_trials` runs it.

The choice is recorded where labels are written (benchmark metadata ``"simulator"``, the GSR
evaluator's details), so a number always says which engine produced it.
"""

from __future__ import annotations

import functools
import importlib.util
import subprocess
import sys
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from importlib import metadata
from typing import Any, Literal

from dg16m_core.checks import check_integer, known_fields
from dg16m_core.errors import Dg16mError

SimulatorName = Literal["mujoco", "warp"]
SIMULATORS: tuple[str, ...] = ("mujoco", "warp")

WARP_EXTRA = "pip install 'dg16m[warp]'"
"""How to install the optional MuJoCo Warp dependencies."""


class SimulatorError(Dg16mError, ValueError):
    """Bad simulator settings, a missing optional extra or an unavailable device."""


@dataclass(frozen=True)
class Simulator:
    """The physics engine for trials and its settings.

    Attributes:
        name: ``"mujoco"`` (C MuJoCo, float64, CPU) or ``"warp"`` (MuJoCo Warp, float32).
        device: Warp device for ``"warp"``: ``"cuda"``, ``"cuda:1"``, ... or ``"cpu"`` (Warp's
            CPU device: slow, for checking without a GPU). ``None`` means ``"cuda:0"``. Must be
            ``None`` for ``"mujoco"``.
        worlds: ``"warp"``: most trials of one object simulated at once (Warp worlds; GPU
            memory grows with it, about linearly).
        nconmax: ``"warp"``: contacts allocated per world (the pool is shared by all worlds).
        njmax: ``"warp"``: constraint rows allocated per world. A world that runs out of either
            is ``UNSTABLE`` (a failure that is reported, never dropped).
        deterministic: ``"warp"``: ask MuJoCo Warp for run-to-run determinism (stable contact
            order, canonical constraint rows, order-invariant atomic sums; slower). Without it
            two GPU runs of the same trials may differ in the last bits, which contact chaos
            can grow into another verdict (see BENCHMARKS.md).
        graph: ``"warp"`` on CUDA: replay each step as a captured CUDA graph (fewer launches).
    """

    name: SimulatorName = "mujoco"
    device: str | None = None
    worlds: int = 4096
    nconmax: int = 64
    njmax: int = 256
    deterministic: bool = False
    graph: bool = True

    def __post_init__(self) -> None:
        if self.name not in SIMULATORS:
            raise SimulatorError(
                f"simulator: expected one of {', '.join(SIMULATORS)}, found {self.name!r}"
            )
        if self.name == "mujoco" and self.device is not None:
            raise SimulatorError(
                f"device: expected none for the 'mujoco' simulator (it runs on the CPU), found "
                f"{self.device!r}"
            )
        if self.device is not None and (not isinstance(self.device, str) or not self.device):
            raise SimulatorError(
                f"device: expected a Warp device name such as 'cuda:0' or 'cpu', found "
                f"{self.device!r}"
            )
        for name in ("worlds", "nconmax", "njmax"):
            check_integer(name, getattr(self, name), minimum=1, error=SimulatorError)
        for name in ("deterministic", "graph"):
            if not isinstance(getattr(self, name), bool):
                raise SimulatorError(
                    f"{name}: expected true or false, found {getattr(self, name)!r}"
                )

    @property
    def is_default(self) -> bool:
        """C MuJoCo, the reference engine."""
        return self.name == "mujoco"

    @property
    def warp_device(self) -> str:
        """The Warp device name (``"cuda:0"`` when :attr:`device` is ``None``)."""
        return self.device or "cuda:0"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings; for ``"mujoco"`` only the name (the Warp settings do not apply)."""
        if self.name == "mujoco":
            return {"name": "mujoco"}
        out = asdict(self)
        out["device"] = self.warp_device
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Simulator:
        """The settings :meth:`to_dict` wrote (missing keys take their defaults).

        Raises:
            SimulatorError: not a mapping, unknown keys or bad values.
        """
        values = known_fields(cls, data, what="simulator", error=SimulatorError)
        if values.get("name", "mujoco") == "mujoco":
            values.pop("device", None)
        return cls(**values)

    def describe(self) -> dict[str, Any]:
        """:meth:`to_dict` plus the engine's versions (for provenance in outputs)."""
        import mujoco

        out = self.to_dict()
        out["mujoco"] = mujoco.__version__
        if self.name == "warp":  # read from the installed metadata: importing Warp here could
            # initialise CUDA in a process that later forks workers
            for key, dist in (("mujoco_warp", "mujoco-warp"), ("warp", "warp-lang")):
                try:
                    out[key] = metadata.version(dist)
                except metadata.PackageNotFoundError:
                    out[key] = "not installed"
        return out

    def check_available(self) -> None:
        """Raise now, with the fix, if this simulator cannot run here (missing extra, no such
        device), rather than after a benchmark's first object.

        The device is probed in a short-lived child process: initialising CUDA here would
        break the worker processes a pool forks from this one.

        Raises:
            SimulatorError: the extra is not installed or the device does not exist.
        """
        if self.name == "mujoco":
            return
        if not warp_installed():
            import_warp()  # raises with the install command
        if self.warp_device == "cpu":
            return
        problem = _device_problem(self.warp_device)
        if problem is not None:
            raise SimulatorError(
                f"device: expected a Warp device that exists here, found {self.warp_device!r} "
                f"({problem}); use device 'cpu' to run MuJoCo Warp on the CPU for checking"
            )


@functools.cache
def _device_problem(device: str) -> str | None:
    """Why Warp cannot use ``device`` (``None``: it can), probed once per process and device in
    a child process (:data:`_DEVICE_PROBE`): a build checks before its objects, its evaluator
    before scoring, and the answer does not change in between."""
    probe = subprocess.run(
        [sys.executable, "-c", _DEVICE_PROBE, device],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    if probe.returncode == 0:
        return None
    lines = (probe.stderr or probe.stdout).strip().splitlines()
    return lines[-1] if lines else "no message"


_DEVICE_PROBE = """
import sys
import warp as wp
wp.config.quiet = True
try:
    wp.get_device(sys.argv[1])
except Exception as exc:  # any failure of the probe is the message
    sys.exit(f"{type(exc).__name__}: {exc} ({wp.get_cuda_device_count()} CUDA device(s))")
"""
"""Run in a child process by :func:`_device_problem`."""


def warp_installed() -> bool:
    """True when the optional ``warp`` extra (``mujoco_warp`` and ``warp``) is importable."""
    return all(importlib.util.find_spec(m) is not None for m in ("mujoco_warp", "warp"))


def import_warp() -> tuple[Any, Any]:
    """``(mujoco_warp, warp)``, imported quietly.

    Raises:
        SimulatorError: the optional extra is not installed (the message says how).
    """
    if not warp_installed():
        raise SimulatorError(
            f"simulator 'warp': expected the optional MuJoCo Warp packages, found them missing; "
            f"install them with {WARP_EXTRA}"
        )
    import warp as wp

    wp.config.quiet = True  # no banner
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)  # no per-module load lines
    import mujoco_warp as mjw

    return mjw, wp


def check_simulator(value: Simulator | str | None) -> Simulator:
    """A :class:`Simulator` from itself, a name (``"mujoco"``, ``"warp"``) or ``None`` (the
    default C MuJoCo).

    Raises:
        SimulatorError: anything else.
    """
    if value is None:
        return Simulator()
    if isinstance(value, Simulator):
        return value
    if isinstance(value, str):
        return Simulator(name=value)  # type: ignore[arg-type]
    raise SimulatorError(
        f"simulator: expected a Simulator or one of {', '.join(SIMULATORS)}, found "
        f"{type(value).__name__}"
    )


def add_simulator_arguments(parser: Any) -> None:
    """``--simulator``, ``--device`` and ``--worlds``: the engine of a command that runs trials
    (``dg16m sim run``, ``dg16m benchmark build``, ``dg16m evaluate``)."""
    group = parser.add_argument_group("physics engine")
    group.add_argument(
        "--simulator",
        choices=SIMULATORS,
        default="mujoco",
        help="mujoco: C MuJoCo on the CPU (default, the reference); warp: MuJoCo Warp, one "
        f"object's trials batched on a GPU ({WARP_EXTRA})",
    )
    group.add_argument(
        "--device",
        default=None,
        help="--simulator warp: the Warp device (default cuda:0; 'cpu' runs Warp on the CPU, "
        "slowly, for checking)",
    )
    group.add_argument(
        "--worlds",
        type=int,
        default=Simulator.worlds,
        help=f"--simulator warp: trials stepped at once (default {Simulator.worlds})",
    )
    group.add_argument(
        "--deterministic",
        action="store_true",
        help="--simulator warp: run-to-run deterministic GPU results (slower)",
    )


def simulator_from_args(args: Any) -> Simulator:
    """The :class:`Simulator` that :func:`add_simulator_arguments`'s options name.

    Raises:
        SimulatorError: Warp options given with ``--simulator mujoco``, or bad values.
    """
    if args.simulator == "mujoco":
        given = [
            option
            for option, value, default in (
                ("--device", args.device, None),
                ("--worlds", args.worlds, Simulator.worlds),
                ("--deterministic", args.deterministic, False),
            )
            if value != default
        ]
        if given:
            raise SimulatorError(
                f"{', '.join(given)}: expected --simulator warp with these options, found "
                "--simulator mujoco"
            )
        return Simulator()
    return Simulator(
        name="warp", device=args.device, worlds=args.worlds, deterministic=args.deterministic
    )
