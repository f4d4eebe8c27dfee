"""Type stubs of the compiled layer (``hal-sim/python/src/lib.rs``). Units: SI, named in keys."""

import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

__version__: str

class RegenError(ValueError):
    """Refused input; the message is the ``regen`` command line's (key, value, allowed range)."""

class Scenario:
    """A scenario (the TOML ``regen run`` reads), validated on every change; pickles as its TOML."""

    @staticmethod
    def from_toml(text: str) -> "Scenario":
        """Parse scenario TOML text; errors name the key and line."""
    @staticmethod
    def from_file(path: Union[str, "os.PathLike[str]"]) -> "Scenario":
        """Read a scenario file as ``regen run FILE`` does (message prefixed by the path)."""
    @staticmethod
    def tmd(r_load_ohm: float = 306.0) -> "Scenario":
        """The reference TMD (400 kg, 2 s, base sine 1 m/s² at 0.5 Hz; 12 s, averages after
        8 s) with an emulated resistor of ``r_load_ohm`` Ω per phase."""
    def to_toml(self) -> str:
        """The scenario as TOML text."""
    def to_dict(self) -> Dict[str, Any]:
        """The scenario as nested dicts (its TOML tables)."""
    def get(self, key: str) -> Any:
        """A value by dotted scenario path (``law.r_load_ohm``, ``drive.excitation.seed``) or
        firmware registry name (``trk_period_s``; from ``[law.set]`` or the configuration)."""
    def set(self, key: str, value: Any) -> None:
        """Set a value (sweep name, registry name or dotted path) and validate the scenario as
        ``regen`` does; on refusal raise :class:`RegenError` and change nothing."""
    def copy(self) -> "Scenario":
        """A copy."""
    @property
    def name(self) -> str: ...
    @property
    def duration_s(self) -> float:
        """Simulated time, s."""
    @property
    def settle_s(self) -> float:
        """Time after which averages are taken, s."""
    def __eq__(self, other: object) -> bool: ...
    def __reduce__(self) -> Tuple[Any, Tuple[str]]: ...

def simulate(scenario: Scenario, record: bool = True) -> Dict[str, Any]:
    """One closed-loop run with the GIL released: ``channels`` (name → float64 array),
    ``energy`` and ``energy_at_settle`` (J), ``fault``, ``faults_text``, ``steps``,
    ``settle_step``, ``period_s`` (s), ``wall_s`` (s), ``summary``."""

def sizing(ke_paper: float = 0.77) -> Dict[str, Dict[str, float]]:
    """Sizing indices of the reference device: ``paper`` and ``consistent``."""

def tmd_power(scenario: Scenario, r_load_ohm: Sequence[float]) -> Dict[str, Any]:
    """Harmonic-balance TMD power at each load (Ω): arrays and ``r_opt_ohm``."""

def design_two_way(r_on_ohm: float = 0.0) -> Dict[str, Any]:
    """Two-way (LQG) controller for the reference model: ``opt`` and predicted powers (W)."""

def diagnose_csv(
    text: str,
    cross_text: Optional[str] = None,
    cutoff_hz: Optional[float] = None,
    filter_force: bool = False,
    min_gain: float = 0.02,
) -> Tuple[str, str, str]:
    """``regen diagnose`` on CSV text: (report JSON, extended model TOML, text report)."""

def names() -> Dict[str, List[str]]:
    """``channels`` the recorder knows and the firmware registry's ``parameters``."""
