"""Type stubs of the Rust extension `backdrive_rig._native` (hand-kept beside it, checked by
tests/test_stubs.py). Use the `backdrive_rig` package; this layer returns JSON text and
column bytes that the package turns into objects, arrays and DataFrames."""

from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

TELEMETRY_COLUMNS: List[str]
DEFAULT_BAUD_RATE: int
MAX_STREAM_RATE_HZ: int
STREAM_COLUMNS: List[str]
HOLD_RELEASE_DEFAULTS: Dict[str, Optional[float]]

class RigError(Exception):
    """Any error of the rig library; the message is the CLI's. The base of every other."""

class BadValueError(RigError, ValueError):
    """A value the device or the library does not take; the message names it and the range. Also a ValueError."""

class MissingFileError(BadValueError, FileNotFoundError):
    """A file given does not exist; the message names it. Also a BadValueError and a FileNotFoundError."""

class RefusedError(RigError):
    """The device refused a request (a Nack); the message says why and what to do."""

class NoReplyError(RigError, TimeoutError):
    """The device did not answer (after retries); the message says what to check. Also a TimeoutError."""

class VersionMismatchError(RigError):
    """The device speaks another protocol version or schema; the message says which side to update."""

class LinkError(RigError, OSError):
    """The port could not be opened or failed (busy, gone, not a device). Also an OSError."""

class DeviceFaultError(RigError):
    """The device latched a fault; the message names it."""

class RigClosedError(RigError):
    """The rig was closed (its port's thread has ended)."""

#: A procedure's progress: (points done, all points, the line `rig` prints); the counts
#: are None on a line without them.
Progress = Callable[[Optional[int], Optional[int], str], None]

#: (name, dtype, little-endian bytes or list of str) per column.
Columns = List[Tuple[str, str, Union[bytes, List[str]]]]

class NativeReleaseStatus:
    def __init__(self) -> None: ...
    @property
    def live(self) -> bool: ...
    @property
    def ended_by(self) -> Optional[str]: ...
    def confirm(self) -> None: ...

class NativeRecording:
    @property
    def rate_hz(self) -> int: ...
    @property
    def done(self) -> bool: ...
    @property
    def lost(self) -> int: ...
    @property
    def gaps(self) -> List[Tuple[int, int]]: ...
    @property
    def error(self) -> Optional[str]: ...
    @property
    def stream(self) -> bool: ...
    def __len__(self) -> int: ...
    def columns(self, take: bool = False) -> Columns: ...

class NativeRig:
    @staticmethod
    def open(port: str, baud: int = 921600) -> NativeRig: ...
    @staticmethod
    def virtual_rig(
        preset: str = "paper",
        effects: Sequence[str] = ...,
        model: Optional[Union[str, PathLike[str]]] = None,
        speed: float = 1.0,
        seed: int = 1,
    ) -> NativeRig: ...
    @property
    def port(self) -> str: ...
    def info(self) -> str: ...
    def faults(self) -> str: ...
    def clear(self) -> str: ...
    def parameters(self) -> str: ...
    def set_parameters(self, toml_text: str, name: str) -> str: ...
    def start_release(
        self,
        freq_hz: float,
        seconds: Optional[float],
        confirm_s: Optional[float],
        status: NativeReleaseStatus,
    ) -> None: ...
    def stop_release(self, why: str) -> None: ...
    def start_recording(
        self, rate_hz: int, seconds: Optional[float], stream: bool = False
    ) -> NativeRecording: ...
    def wait_samples(self, recording: NativeRecording, samples: int) -> None: ...
    def stop_recording(self, recording: NativeRecording) -> None: ...
    def wait_recording(self, recording: NativeRecording) -> None: ...
    def capture(self, seconds: float, rate_hz: int) -> Tuple[str, Columns]: ...
    def torque_sweep(
        self,
        plan: str,
        plan_name: str,
        window_revolutions: bool = False,
        progress: Optional[Progress] = None,
    ) -> Tuple[str, str]: ...
    def discover(
        self,
        csv: str,
        max_points: int = 60,
        seed: int = 1,
        replicates: int = 200,
        model: Optional[str] = None,
        force: bool = False,
        progress: Optional[Progress] = None,
    ) -> str: ...
    def hold_release(
        self,
        load_nm: Optional[float],
        hold_s: float,
        freq_hz: float,
        release_s: float,
        after_s: float,
    ) -> str: ...
    def link_stats(self) -> str: ...
    def close(self) -> None: ...

def design(
    z: Optional[Sequence[int]] = None,
    x: Optional[Sequence[float]] = None,
    table1: bool = False,
    eta_gross: Optional[float] = None,
    module_mm: Optional[float] = None,
    pressure_angle_deg: Optional[float] = None,
    mu_s: Optional[float] = None,
    mu_d: Optional[float] = None,
    eccentricity_mm: Optional[float] = None,
    carrier_mass_kg: Optional[float] = None,
    tau_rot_nm: Optional[float] = None,
    freq_hz: Optional[float] = None,
    max_current_a: Optional[float] = None,
) -> str: ...
def explain(
    csv: Union[str, PathLike[str]],
    model: Optional[Union[str, PathLike[str]]] = None,
    alpha: Optional[float] = None,
    folds: Optional[int] = None,
    replicates: Optional[int] = None,
    stated_noise_ma: Optional[float] = None,
    propose: bool = False,
) -> str: ...
def compare(
    measured: Union[str, PathLike[str]],
    model: Optional[Union[str, PathLike[str]]] = None,
    rig: Optional[Union[str, PathLike[str]]] = None,
    seed: int = 1,
) -> str: ...
def versions() -> Tuple[str, int, str]: ...
