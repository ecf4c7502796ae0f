"""backdrive_rig: the backdrive rig (a 2K-H planetary gear switched between holding and
backdrivable by vibration), its virtual rig, ``explain`` and ``design`` from Python.

A thin door onto the Rust host library of the ``rig`` command-line tool: the same client,
procedures, checks and error messages. A Rust thread owns each rig's port; every blocking
call releases the GIL, and Ctrl-C (KeyboardInterrupt) stops a call with the gear locked.

    >>> from backdrive_rig import Rig
    >>> with Rig.virtual(speed=10) as rig:
    ...     with rig.release(freq_hz=10, seconds=2):
    ...         df = rig.record(seconds=2, rate_hz=1000)

Results carry the CLI's ``--json`` keys (``rig info --json`` ...), data the columns and
units of the CLI's CSV files (``rig monitor --csv``, ``rig capture --csv``, ``rig experiment
torque-sweep --csv``).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import threading
from types import TracebackType
from typing import (
    TYPE_CHECKING,
    Any,
    Callable,
    Dict,
    Iterable,
    Iterator,
    List,
    Mapping,
    Optional,
    Sequence,
    Tuple,
    Type,
    Union,
    overload,
)

from typing import Literal



import numpy as np

if TYPE_CHECKING:  # pandas is imported where a DataFrame is made, not at import time
    import pandas as pd

from . import _native
from ._native import (
    BadValueError,
    DeviceFaultError,
    LinkError,
    MissingFileError,
    NoReplyError,
    RefusedError,
    RigClosedError,
    RigError,
    VersionMismatchError,
)

__all__ = [
    "Rig",
    "Release",
    "Recorder",
    "Stream",
    "Report",
    "design",
    "explain",
    "compare",
    "discover",
    "versions",
    "TELEMETRY_COLUMNS",
    "STREAM_COLUMNS",
    "RigError",
    "BadValueError",
    "MissingFileError",
    "RefusedError",
    "NoReplyError",
    "VersionMismatchError",
    "LinkError",
    "DeviceFaultError",
    "RigClosedError",
]

#: What a recording or a capture returns: a DataFrame, or with ``pandas=False`` a dict of
#: numpy arrays (a capture's also has its ``"summary"`` dict).
Frame = Union["pd.DataFrame", Dict[str, Any]]

#: A long procedure's progress callback: ``progress(done, total, line)`` with the points
#: done and all points (None on a line without them) and the line ``rig`` prints, which
#: ends with the time elapsed and an estimate of the time left.
Progress = Callable[[Optional[int], Optional[int], str], None]


def _progress(progress: Union[Progress, bool, None], what: str) -> Tuple[Optional[Progress], Callable[[], None]]:
    """The callback a procedure reports to, and what closes it: ``progress`` itself; by
    default (None or True) a tqdm bar when tqdm is installed, else nothing; False: nothing."""
    if callable(progress):
        return progress, lambda: None
    if progress is False:
        return None, lambda: None
    try:
        from tqdm.auto import tqdm  # type: ignore[import-untyped, unused-ignore]
    except ImportError:
        return None, lambda: None
    bar = tqdm(desc=what, unit="point")

    def update(done: Optional[int], total: Optional[int], line: str) -> None:
        if done is None or total is None:
            return
        bar.total = total
        bar.update(done - bar.n)

    return update, bar.close


#: The columns of ``rig monitor --csv`` (telemetry), in order; ``record`` adds ``seq``.
TELEMETRY_COLUMNS: List[str] = list(_native.TELEMETRY_COLUMNS)
#: The continuous stream's columns (``rig record``'s CSV columns and units, without its
#: ``lost`` rows: a recording's ``lost`` and ``gaps`` say which samples never arrived).
STREAM_COLUMNS: List[str] = list(_native.STREAM_COLUMNS)

PathLike = Union[str, "os.PathLike[str]"]

# `rig experiment hold-release`'s defaults (Fig. 5), from the host library.
_FIG5: Dict[str, Any] = dict(_native.HOLD_RELEASE_DEFAULTS)


def _int_arg(name: str, value: Any, lo: int, hi: int) -> int:
    """``value`` as a whole number in ``[lo, hi]``, else BadValueError naming ``name``."""
    if isinstance(value, bool):
        raise BadValueError(f"{name} {value!r}: give a whole number from {lo} to {hi}")
    try:
        as_float = float(value)
        whole = int(value)
    except (TypeError, ValueError, OverflowError):
        raise BadValueError(f"{name} {value!r}: give a whole number from {lo} to {hi}") from None
    if not math.isfinite(as_float) or whole != as_float or not lo <= whole <= hi:
        raise BadValueError(f"{name} {value!r}: give a whole number from {lo} to {hi}")
    return whole


def _float_arg(name: str, value: Any) -> float:
    """``value`` as a finite float, else BadValueError naming ``name`` (the range is the
    library's to check)."""
    try:
        out = float(value)
    except (TypeError, ValueError, OverflowError):
        raise BadValueError(f"{name} {value!r}: give a number") from None
    if not math.isfinite(out):
        raise BadValueError(f"{name} {value!r}: give a finite number")
    return out


class Report(Dict[str, Any]):
    """A result as the CLI's ``--json`` prints it: a dict with the same keys, also
    readable as attributes (``report.verdict`` is ``report["verdict"]``)."""

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    def __dir__(self) -> Iterable[str]:
        return list(super().__dir__()) + [k for k in self.keys() if isinstance(k, str)]


def _report(text: str) -> Report:
    """The library's JSON object as a Report."""
    value = json.loads(text)
    if not isinstance(value, dict):
        raise RigError(f"the library returned {type(value).__name__}, not an object: report this")
    return Report(value)


def _reports(text: str) -> List[Report]:
    """The library's JSON array of objects as Reports."""
    value = json.loads(text)
    if not isinstance(value, list):
        raise RigError(f"the library returned {type(value).__name__}, not a list: report this")
    return [Report(v) for v in value]


def _frame(columns: Sequence[Any], pandas: bool) -> Frame:
    """Columns (name, dtype, bytes or list) to a DataFrame or a dict of numpy arrays."""
    data: Dict[str, np.ndarray] = {}
    for name, dtype, value in columns:
        if dtype == "str":
            data[name] = np.asarray(value, dtype=object)
        else:
            data[name] = np.frombuffer(value, dtype=dtype).copy()
    if not pandas:
        return data
    import pandas as pd

    return pd.DataFrame(data)


def versions() -> Dict[str, str]:
    """This library's version, protocol version and schema hash (what it asks a device
    for at Hello; a device of another version is refused with VersionMismatchError)."""
    package, protocol, schema = _native.versions()
    return {"package": package, "protocol_version": str(protocol), "schema_hash": schema}


__version__ = _native.versions()[0]


class _Required:
    """The default of an argument that must be given (``None`` is a value there)."""

    def __repr__(self) -> str:
        return "<required>"


_REQUIRED = _Required()


class Release:
    """A release (vibration on: the gear is backdrivable and a load can move), kept alive by
    heartbeats from a Rust thread. Use it as a context manager::

        with rig.release(freq_hz=10, seconds=5):
            ...

    The gear is locked again when the block ends, on any exception (KeyboardInterrupt
    included), when ``seconds`` of device time have passed (even while Python is busy or
    hung), when the rig is closed or dropped, and, if the process dies, within the device's
    comms timeout (500 ms). A release without a duration (``seconds=None``) lasts only
    while Python calls :meth:`confirm` at least every ``confirm_s`` (device) seconds.
    """

    def __init__(self, rig: "Rig", freq_hz: float, seconds: Optional[float], confirm_s: Optional[float]):
        self._rig = rig
        self.freq_hz = _float_arg("freq_hz", freq_hz)
        self.seconds = None if seconds is None else _float_arg("seconds", seconds)
        self.confirm_s = None if confirm_s is None else _float_arg("confirm_s", confirm_s)
        self._status = _native.NativeReleaseStatus()

    def start(self) -> "Release":
        """Starts vibrating (checked against the calibration's frequency range)."""
        self._rig._native.start_release(self.freq_hz, self.seconds, self.confirm_s, self._status)
        return self

    def stop(self) -> None:
        """Locks the gear (ends the release); harmless when it already ended."""
        self._rig._native.stop_release("stop")

    def confirm(self) -> None:
        """Confirms that the program is alive (releases without a duration)."""
        self._status.confirm()

    @property
    def live(self) -> bool:
        """Whether the release is still live."""
        return bool(self._status.live)

    @property
    def ended_by(self) -> Optional[str]:
        """How it ended: ``duration``, ``stop``, ``exception``, ``keep-alive`` (not
        confirmed in time), ``rig closed``; None while live."""
        ended: Optional[str] = self._status.ended_by
        return ended

    def __enter__(self) -> "Release":
        # A release started with start() may be handed to `with` to get its locking.
        return self if self.live else self.start()

    def __exit__(
        self,
        exc_type: Optional[Type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> Literal[False]:
        why = "stop" if exc_type is None else "exception"
        try:
            self._rig._native.stop_release(why)
        except KeyboardInterrupt:
            # A second Ctrl-C while locking: lock again, then let it propagate.
            self._rig._native.stop_release(why)
            raise
        return False

    def __del__(self) -> None:
        try:
            if self._status.live:
                self._rig._native.stop_release("dropped")
        except Exception:
            pass


class Recorder:
    """A background telemetry recording: the port's Rust thread stores every sample while
    Python does other work. Samples lost on the link (gaps in the device's sample counter)
    are counted in :attr:`lost` and listed in :attr:`gaps`, never hidden. Above 1 kHz (or
    with ``stream=True``) it records the continuous stream instead: every ADC sample and
    its control step, up to 10 kHz, with :data:`STREAM_COLUMNS`."""

    def __init__(self, rig: "Rig", native: Any):
        self._rig = rig
        self._native = native

    @property
    def rate_hz(self) -> int:
        """Telemetry rate, Hz."""
        return int(self._native.rate_hz)

    @property
    def done(self) -> bool:
        """Whether the recording has ended."""
        return bool(self._native.done)

    @property
    def lost(self) -> int:
        """Samples missing from the stream so far."""
        return int(self._native.lost)

    @property
    def gaps(self) -> List[Tuple[int, int]]:
        """(sequence number before, after) of each gap."""
        return list(self._native.gaps)

    @property
    def stream(self) -> bool:
        """Whether this records the continuous stream (:data:`STREAM_COLUMNS`), not
        telemetry (:data:`TELEMETRY_COLUMNS`)."""
        return bool(self._native.stream)

    def __len__(self) -> int:
        return len(self._native)

    def wait(self) -> "Recorder":
        """Waits until a recording with a duration has ended (GIL released)."""
        self._rig._native.wait_recording(self._native)
        self._raise_error()
        return self

    def stop(self) -> "Recorder":
        """Stops the recording and the telemetry stream; a recorder another thread waits
        for starts next."""
        try:
            self._rig._native.stop_recording(self._native)
        finally:
            self._rig._recording_ended(self)
        return self

    def _raise_error(self) -> None:
        err = self._native.error
        if err is not None:
            raise RigError(f"the recording stopped: {err}")

    @overload
    def take(self, pandas: Literal[True] = True) -> "pd.DataFrame": ...
    @overload
    def take(self, pandas: Literal[False]) -> Dict[str, Any]: ...
    @overload
    def take(self, pandas: bool) -> Frame: ...
    def take(self, pandas: bool = True) -> Frame:
        """The samples recorded since the last take (the buffer is emptied)."""
        return self._result(self._native.columns(True), pandas)

    @overload
    def data(self, pandas: Literal[True] = True) -> "pd.DataFrame": ...
    @overload
    def data(self, pandas: Literal[False]) -> Dict[str, Any]: ...
    @overload
    def data(self, pandas: bool) -> Frame: ...
    def data(self, pandas: bool = True) -> Frame:
        """All samples held (the buffer is kept)."""
        return self._result(self._native.columns(False), pandas)

    def _result(self, columns: Any, pandas: bool) -> Frame:
        out: Any = _frame(columns, pandas)
        if pandas:
            out.attrs["lost"] = self.lost
            out.attrs["gaps"] = self.gaps
            out.attrs["rate_hz"] = self.rate_hz
        return out

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(
        self,
        exc_type: Optional[Type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> Literal[False]:
        self.stop()
        return False


class Stream:
    """The continuous stream as numpy chunks: every ADC sample and its control step (up to
    10 kHz), each chunk a dict of numpy arrays with :data:`STREAM_COLUMNS`. Iterate it (each
    chunk waits, GIL released, until ``chunk_samples`` arrived or the stream ended) inside a
    ``with`` block, which stops the stream on the way out::

        with rig.stream(rate_hz=10000, seconds=60) as s:
            for chunk in s:
                np.mean(chunk["current_a"])

    Samples that never arrived (the link was full, or a frame was damaged) are counted in
    :attr:`lost` and placed in :attr:`gaps`, never hidden: ``chunk["seq"]`` jumps there."""

    def __init__(self, recorder: Recorder, chunk_samples: int):
        self._rec = recorder
        self._chunk = chunk_samples
        self.samples = 0
        """Samples yielded so far."""

    @property
    def rate_hz(self) -> int:
        """The stream's rate, Hz."""
        return self._rec.rate_hz

    @property
    def done(self) -> bool:
        """Whether the stream has ended (its ``seconds``, or stopped)."""
        return self._rec.done

    @property
    def lost(self) -> int:
        """Samples that never arrived so far."""
        return self._rec.lost

    @property
    def gaps(self) -> List[Tuple[int, int]]:
        """(sample number before, after) of each run of lost samples."""
        return self._rec.gaps

    def stop(self) -> None:
        """Stops the stream (samples not yet taken stay for :meth:`take`)."""
        self._rec.stop()

    def take(self) -> Dict[str, np.ndarray]:
        """The samples received since the last chunk, at once."""
        data: Dict[str, np.ndarray] = self._rec.take(pandas=False)
        self.samples += len(data["seq"])
        return data

    def __iter__(self) -> Iterator[Dict[str, np.ndarray]]:
        return self

    def __next__(self) -> Dict[str, np.ndarray]:
        rig = self._rec._rig
        rig._native.wait_samples(self._rec._native, self._chunk)
        self._rec._raise_error()
        if len(self._rec) == 0:
            raise StopIteration
        return self.take()

    def __enter__(self) -> "Stream":
        return self

    def __exit__(
        self,
        exc_type: Optional[Type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> Literal[False]:
        self.stop()
        return False


class Rig:
    """A rig: a board on a serial port, a served virtual rig (``rig sim serve``), or the
    in-process virtual rig. Thread-safe: calls from several Python threads are queued to
    the one Rust thread that owns the port. Use as a context manager, or call
    :meth:`close` (the gear is locked)."""

    def __init__(self, native: Any):
        self._native = native
        # One recording at a time: other threads' recorders queue here (see recorder()).
        self._recording_turn = threading.Condition()
        self._recording_live: Optional[Recorder] = None
        self._recording_thread: Optional[int] = None

    @classmethod
    def open(cls, port: str, baud: int = _native.DEFAULT_BAUD_RATE) -> "Rig":
        """Opens the board or served virtual rig on ``port`` and says Hello; a device of
        another protocol version or schema raises VersionMismatchError naming which side
        to update."""
        return cls(_native.NativeRig.open(str(port), _int_arg("baud", baud, 1, 2**32 - 1)))

    @classmethod
    def virtual(
        cls,
        preset: str = "paper",
        effects: Sequence[str] = (),
        model: Optional[PathLike] = None,
        speed: float = 1.0,
        seed: int = 1,
    ) -> "Rig":
        """Starts the in-process virtual rig (the firmware's control core and the plant):
        ``preset`` ``paper`` or ``ideal``, hidden ``effects`` as ``NAME[:k=v,...]`` (``rig
        explain``'s names), ``model`` a rig file, ``speed`` virtual seconds per wall
        second (at most 100). As ``rig sim serve``'s options."""
        return cls(
            _native.NativeRig.virtual_rig(
                str(preset),
                [str(e) for e in effects],
                None if model is None else os.fspath(model),
                _float_arg("speed", speed),
                _int_arg("seed", seed, 0, 2**64 - 1),
            )
        )

    @property
    def port(self) -> str:
        """The port's path: the board's serial port, or the pseudo-terminal of a virtual
        rig (``/dev/pts/N``)."""
        return str(self._native.port)

    def info(self) -> Report:
        """Device identity and versions: ``rig info --json``'s keys."""
        return _report(self._native.info())

    def faults(self) -> Report:
        """Active and latched faults: ``rig faults --json``'s keys (``active``, ``latched``)."""
        return _report(self._native.faults())

    def clear(self) -> Report:
        """Clears latched faults whose cause is gone: ``rig clear --json``'s keys."""
        return _report(self._native.clear())

    def parameters(self) -> Dict[str, Dict[str, Any]]:
        """The device's calibration record as the rig file's sections (docs/rig-file.md):
        ``{"gear": {...}, "calibration": {...}, "limits": {...}, ...}``."""
        sections: Dict[str, Dict[str, Any]] = json.loads(self._native.parameters())
        return sections

    def set_parameters(
        self, rig_file: Optional[PathLike] = None, **sections: Mapping[str, Any]
    ) -> Report:
        """Writes a calibration to the device, checked as ``rig calibration set`` checks it
        (the rig file's rules, then the device's: a refusal names the field), and reads it
        back. Either a rig file's path, or sections to change, merged over the device's
        current ones (``set_parameters(limits={"max_freq_hz": 12})``): a key not given
        keeps its value on the device. Returns ``changed``, ``written``, ``defaulted``
        (and ``calibration`` when written)."""
        if rig_file is not None and sections:
            raise BadValueError("set_parameters: give a rig file or sections, not both")
        if rig_file is not None:
            path = os.fspath(rig_file)
            try:
                with open(path, "r", encoding="utf-8") as f:
                    text = f.read()
            except FileNotFoundError as e:
                raise MissingFileError(f"rig file {path}: cannot read it ({e})") from None
            except OSError as e:
                raise BadValueError(f"rig file {path}: cannot read it ({e})") from None
            return _report(self._native.set_parameters(text, path))
        if not sections:
            raise BadValueError("set_parameters: give a rig file or sections to change")
        merged = self.parameters()
        for name, keys in sections.items():
            if not isinstance(keys, Mapping):
                raise BadValueError(
                    f"set_parameters: section {name} must be a dict of keys (e.g. limits={{'max_freq_hz': 12}})"
                )
            merged.setdefault(name, {}).update(keys)
        return _report(self._native.set_parameters(_toml(merged), "set_parameters"))

    def release(
        self,
        freq_hz: float = 10.0,
        seconds: Union[float, None, "_Required"] = _REQUIRED,
        confirm_s: Optional[float] = None,
    ) -> Release:
        """A release at ``freq_hz`` for ``seconds`` of device time (required: pass
        ``seconds=None, confirm_s=...`` to opt out of a duration, then call
        ``Release.confirm()`` within every ``confirm_s`` device seconds). Use with ``with``."""
        if isinstance(seconds, _Required):
            raise BadValueError(
                "release: give seconds (the release's duration, device s), or seconds=None with confirm_s to keep it by Release.confirm()"
            )
        if seconds is None and confirm_s is None:
            raise BadValueError(
                "release: seconds=None needs confirm_s: the release then lasts while Release.confirm() is called within every confirm_s seconds"
            )
        return Release(self, freq_hz, seconds, confirm_s)

    def recorder(
        self, rate_hz: int = 1000, seconds: Optional[float] = None, stream: Optional[bool] = None
    ) -> Recorder:
        """Starts a background telemetry recording at ``rate_hz`` (the device's 1 kHz
        divided by a whole number) for ``seconds`` of device time, or until ``stop()``.
        Above 1000 Hz, or with ``stream=True``, it records the continuous stream instead
        (every sample at 10 kHz divided by a whole number, :data:`STREAM_COLUMNS`; a rate
        the device cannot stream is refused naming the rate that fits). One recording runs
        at a time: a call from another thread while one runs waits (queues) until it ends
        or is stopped; the same thread gets BadValueError."""
        rate = _int_arg("rate_hz", rate_hz, 1, 2**32 - 1)
        streamed = rate > 1000 if stream is None else bool(stream)
        secs = None if seconds is None else _float_arg("seconds", seconds)
        me = threading.get_ident()
        with self._recording_turn:
            while self._recording_live is not None and not self._recording_live.done:
                if self._recording_thread == me:
                    raise BadValueError(
                        "record: a recording is already running on this rig in this thread: stop it first"
                    )
                self._recording_turn.wait(0.05)
            native = self._native.start_recording(rate, secs, streamed)
            rec = Recorder(self, native)
            self._recording_live, self._recording_thread = rec, me
            return rec

    def stream(
        self, rate_hz: int = 10000, seconds: Optional[float] = None, chunk_s: float = 0.1
    ) -> Stream:
        """The continuous stream at ``rate_hz`` (10 kHz divided by a whole number) for
        ``seconds`` of device time or until stopped, as numpy chunks of ``chunk_s`` seconds
        of samples (see :class:`Stream`; use it in a ``with`` block). The link carries the
        10 kHz stream at the default 921,600 Bd beside telemetry up to 200 Hz
        (``Rig.open(port, baud=4000000)`` agrees on the fast link, where everything fits)."""
        rate = _int_arg("rate_hz", rate_hz, 1, _native.MAX_STREAM_RATE_HZ)
        chunk = max(1, int(round(_float_arg("chunk_s", chunk_s) * rate)))
        return Stream(self.recorder(rate, seconds, stream=True), chunk)

    def _recording_ended(self, rec: Recorder) -> None:
        with self._recording_turn:
            if self._recording_live is rec:
                self._recording_live, self._recording_thread = None, None
            self._recording_turn.notify_all()

    @overload
    def record(self, seconds: float, rate_hz: int = 1000, pandas: Literal[True] = True) -> "pd.DataFrame": ...
    @overload
    def record(self, seconds: float, rate_hz: int = 1000, *, pandas: Literal[False]) -> Dict[str, Any]: ...
    @overload
    def record(self, seconds: float, rate_hz: int = 1000, pandas: bool = True) -> Frame: ...
    def record(self, seconds: float, rate_hz: int = 1000, pandas: bool = True) -> Frame:
        """Telemetry for ``seconds`` of device time at ``rate_hz``: a DataFrame (or a dict
        of numpy arrays) with ``rig monitor --csv``'s columns and units, plus ``seq``;
        ``attrs["lost"]`` and ``attrs["gaps"]`` report samples lost on the link. Above
        1000 Hz (up to 10 kHz) every sample of the continuous stream, with
        :data:`STREAM_COLUMNS` (``rig record``'s columns)."""
        rec = self.recorder(rate_hz, seconds)
        try:
            rec.wait()
        finally:
            rec.stop()
        return rec.take(pandas)

    @overload
    def capture(self, seconds: float, rate_hz: int = 10000, pandas: Literal[True] = True) -> "pd.DataFrame": ...
    @overload
    def capture(self, seconds: float, rate_hz: int = 10000, *, pandas: Literal[False]) -> Dict[str, Any]: ...
    @overload
    def capture(self, seconds: float, rate_hz: int = 10000, pandas: bool = True) -> Frame: ...
    def capture(self, seconds: float, rate_hz: int = 10000, pandas: bool = True) -> Frame:
        """The raw burst (``rig capture``): ``seconds`` at ``rate_hz`` recorded on the device
        and uploaded; ``rig capture --csv``'s columns (index, t_s, current_adc, current_a,
        encoder_count, cam_angle_rad, output_count, output_angle_rad; the output's are NaN
        on a device without an output encoder). ``attrs`` (or the dict's ``"summary"``) has the
        counters: ``dropped``, ``gaps``, ``completed``."""
        summary, columns = self._native.capture(
            _float_arg("seconds", seconds), _int_arg("rate_hz", rate_hz, 1, 2**32 - 1)
        )
        out: Any = _frame(columns, pandas)
        if pandas:
            out.attrs.update(json.loads(summary))
        else:
            out["summary"] = json.loads(summary)
        return out

    def torque_sweep(
        self,
        plan: Union[str, PathLike, None] = None,
        quick: bool = False,
        window: str = "start",
        plan_toml: Optional[str] = None,
        progress: Union[Progress, bool, None] = None,
    ) -> "pd.DataFrame":
        """The required-torque test of Figs. 8-9 (``rig experiment torque-sweep``): ``plan``
        ``"paper"`` (150 runs, the default), ``"quick"`` (30; or ``quick=True``) or a plan
        file's path (docs/plans.md); or ``plan_toml``, a plan's text (as ``explain(...,
        propose=True).proposal["plan_toml"]`` gives it). Returns a DataFrame with the sweep CSV's columns
        (``rig explain`` reads them); ``attrs`` has the summary (``planned``, ``written``,
        ``skipped``) and ``provenance`` (the CSV's ``#`` header). ``progress``: called
        after every point as ``progress(done, total, line)`` (``Progress``); by default a
        tqdm bar when tqdm is installed (``progress=False``: none)."""
        import pandas as pd

        if window not in ("start", "revolutions"):
            raise BadValueError(f"window {window}: give 'start' or 'revolutions'")
        given = [n for n, v in (("plan", plan), ("quick=True", quick or None), ("plan_toml", plan_toml)) if v is not None]
        if len(given) > 1:
            raise BadValueError(
                f"torque_sweep: give one of plan, quick=True or plan_toml, not {' and '.join(given)}"
            )
        if quick:
            plan = "quick"
        plan = "paper" if plan is None else plan
        if plan_toml is not None:
            text, name = str(plan_toml), "plan_toml"
        elif plan in ("paper", "quick"):
            text, name = str(plan), str(plan)
        else:
            name = os.fspath(plan)
            try:
                with open(name, "r", encoding="utf-8") as f:
                    text = f.read()
            except OSError as e:
                raise BadValueError(f"plan {name}: cannot read it ({e})") from None
        report, close = _progress(progress, "torque sweep")
        try:
            summary, provenance = self._native.torque_sweep(text, name, window == "revolutions", report)
        finally:
            close()
        outcome = json.loads(summary)
        rows = outcome.pop("rows")
        df = pd.DataFrame(rows, columns=_SWEEP_COLUMNS)
        # Empty CSV cells (open loop: no target_hz; no temperature sensor) as NaN.
        for c in _SWEEP_COLUMNS:
            df[c] = pd.to_numeric(df[c])
        df.attrs.update(outcome)
        df.attrs["provenance"] = provenance
        return df

    def discover(
        self,
        csv: PathLike,
        max_points: int = 60,
        seed: int = 1,
        replicates: int = 200,
        model: Optional[PathLike] = None,
        force: bool = False,
        progress: Union[Progress, bool, None] = None,
    ) -> Report:
        """The closed discovery loop on this rig (``rig discover --json``, the same code):
        a quick sweep, ``explain``, the test points its proposal names, repeated until the
        verdict settles or ``max_points`` test points are spent. Every round's rows are
        appended to ``csv`` (a new file; an existing one is refused, and left as it is,
        unless ``force``). ``model``: a rig file (the paper's rig by default). Keys: the
        explanation's (``verdict``, ``effects``, ...) and ``points_used``, ``max_points``,
        ``settled``, ``csv``, ``rounds``. ``progress``: as ``torque_sweep``'s, for each
        round's points."""
        report, close = _progress(progress, "discover")
        try:
            return _report(
                self._native.discover(
                    os.fspath(csv),
                    int(max_points),
                    int(seed),
                    int(replicates),
                    None if model is None else os.fspath(model),
                    bool(force),
                    report,
                )
            )
        finally:
            close()

    def hold_release(
        self,
        load_nm: Optional[float] = _FIG5["load_nm"],
        hold_s: float = _FIG5["hold_s"],
        freq_hz: float = _FIG5["freq_hz"],
        release_s: float = _FIG5["release_s"],
        after_s: float = _FIG5["after_s"],
    ) -> "pd.DataFrame":
        """Fig. 5 (``rig experiment hold-release``): hold ``load_nm`` without vibration for
        ``hold_s``, release at ``freq_hz`` for ``release_s``, record ``after_s`` more (the
        defaults are the CLI's: 1.0 kg on the 75 mm pulley, 14.5 s, 5 Hz, 2 s, 1.5 s;
        ``load_nm=None``: the load already on the rig, nothing is hung). A
        DataFrame with the CSV's columns (t_s, phase, state, output_angle_rad,
        cam_speed_rad_s, current_a); ``attrs["fig5"]``: the verdict numbers."""
        import pandas as pd

        out = json.loads(self._native.hold_release(load_nm, hold_s, freq_hz, release_s, after_s))
        df = pd.DataFrame(out["samples"], columns=_HOLD_COLUMNS)
        for c in ("t_s", "output_angle_rad", "cam_speed_rad_s", "current_a"):
            df[c] = pd.to_numeric(df[c])
        df.attrs["fig5"] = out["fig5"]
        return df

    def link_stats(self) -> Report:
        """Link counters: frames, errors, retries, heartbeats, telemetry samples lost."""
        return _report(self._native.link_stats())

    def close(self) -> None:
        """Locks the gear and closes the port (an in-process virtual rig stops)."""
        self._native.close()

    def __enter__(self) -> "Rig":
        return self

    def __exit__(
        self,
        exc_type: Optional[Type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> Literal[False]:
        self.close()
        return False

    def __repr__(self) -> str:
        return f"Rig(port={self.port!r})"


# Columns of `rig experiment torque-sweep --csv` (experiment::sweep::Row).
_SWEEP_COLUMNS = [
    "point",
    "repeat",
    "t_s",
    "v_in_v",
    "target_hz",
    "omega_n_rad_s",
    "tau_rot_nm",
    "i_in_a",
    "temp_c",
    "tau_cam_est_nm",
    "backdriven",
    "load_kg",
]
# Columns of `rig experiment hold-release --csv`.
_HOLD_COLUMNS = ["t_s", "phase", "state", "output_angle_rad", "cam_speed_rad_s", "current_a"]


def _toml(sections: Mapping[str, Mapping[str, Any]]) -> str:
    """The rig file's sections as TOML text (flat keys, numbers, strings, booleans, lists)."""

    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float)):
            return repr(float(v)) if isinstance(v, float) else str(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, Mapping):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        raise BadValueError(f"set_parameters: {v!r} is not a rig-file value")

    lines: List[str] = []
    for name, keys in sections.items():
        if isinstance(keys, list):
            for entry in keys:
                lines.append(f"[[{name}]]")
                lines.extend(f"{k} = {value(v)}" for k, v in entry.items())
            continue
        lines.append(f"[{name}]")
        lines.extend(f"{k} = {value(v)}" for k, v in keys.items())
    return "\n".join(lines) + "\n"


@overload
def design(
    z: Optional[Sequence[int]] = None,
    x: Optional[Sequence[float]] = None,
    table1: Literal[False] = False,
    eta_gross: Optional[float] = None,
    **rig: float,
) -> Report: ...


@overload
def design(
    z: None = None,
    x: None = None,
    *,
    table1: Literal[True],
    eta_gross: Optional[float] = None,
    **rig: float,
) -> List[Report]: ...


def design(
    z: Optional[Sequence[int]] = None,
    x: Optional[Sequence[float]] = None,
    table1: bool = False,
    eta_gross: Optional[float] = None,
    **rig: float,
) -> Union[Report, List[Report]]:
    """The design calculator (``rig design --json``): tooth counts ``z`` = (Z1, Z2, Z3,
    Z4) (default the paper's rig), profile shifts ``x``, ``eta_gross`` (adds
    ``mu_from_eta``), or ``table1=True`` for the six sets of Table 1 (a list). Rig values
    as keywords: module_mm, pressure_angle_deg, mu_s, mu_d, eccentricity_mm,
    carrier_mass_kg, tau_rot_nm, freq_hz, max_current_a. Keys: z, n, rho,
    contact_ratios, big_lambda, small_lambda, mu_s_lambda, mu_d_lambda, holds_load,
    keeps_moving_after_stop, tau_cam_hat_nm, checks, warnings, ..."""
    allowed = {
        "module_mm",
        "pressure_angle_deg",
        "mu_s",
        "mu_d",
        "eccentricity_mm",
        "carrier_mass_kg",
        "tau_rot_nm",
        "freq_hz",
        "max_current_a",
    }
    unknown = sorted(set(rig) - allowed)
    if unknown:
        raise BadValueError(f"design: unknown option(s) {', '.join(unknown)} (options: {', '.join(sorted(allowed))})")
    for name, values, what in (("z", z, "tooth counts Z1, Z2, Z3, Z4"), ("x", x, "profile shifts x1, x2, x3, x4")):
        if values is not None and (isinstance(values, (str, bytes)) or len(list(values)) != 4):
            raise BadValueError(f"design: {name} {values!r}: give four {what} (e.g. z=[49, 51, 50, 50])")
    text = _native.design(
        None if z is None else [_int_arg(f"z[{i}]", v, 1, 1000) for i, v in enumerate(z)],
        None if x is None else [_float_arg(f"x[{i}]", v) for i, v in enumerate(x)],
        table1,
        None if eta_gross is None else _float_arg("eta_gross", eta_gross),
        **{k: _float_arg(k, v) for k, v in rig.items()},
    )
    return _reports(text) if table1 else _report(text)


def explain(
    data: Any,
    model: Optional[PathLike] = None,
    alpha: Optional[float] = None,
    folds: Optional[int] = None,
    replicates: Optional[int] = None,
    stated_noise_ma: Optional[float] = None,
    propose: bool = False,
) -> Report:
    """The discrepancy workflow (``rig explain --json``) on ``data``: a CSV path, or a
    DataFrame with the sweep's columns (``omega_n_rad_s``, ``tau_rot_nm``, ``i_in_a``;
    optional ``t_s``, ``v_in_v``, ``temp_c``, ``backdriven``), e.g. from
    :meth:`Rig.torque_sweep` (its provenance travels in ``attrs``). ``model``: a rig file.
    Keys: ``verdict``, ``effects``, ``rmse_before_a``, ``rmse_after_a``, ``lack_of_fit``,
    ... (no report folder is written). ``proposal`` (as ``rig explain --propose``) when
    ``propose`` or when the verdict is ambiguous or unexplained: the test points that best
    separate the leading candidates, its plan text in ``proposal["plan_toml"]`` for
    :meth:`Rig.torque_sweep`."""
    if isinstance(data, (str, os.PathLike)):
        return _report(
            _native.explain(os.fspath(data), None if model is None else os.fspath(model), alpha, folds, replicates, stated_noise_ma, propose)
        )
    if not hasattr(data, "to_csv"):
        raise BadValueError("explain: give a CSV path or a pandas DataFrame")
    fd, path = tempfile.mkstemp(suffix=".csv", prefix="backdrive_rig_explain_")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            provenance = getattr(data, "attrs", {}).get("provenance", "")
            f.write(provenance)
            data.to_csv(f, index=False, lineterminator="\n")
        return _report(
            _native.explain(path, None if model is None else os.fspath(model), alpha, folds, replicates, stated_noise_ma, propose)
        )
    finally:
        os.unlink(path)


def discover(rig: "Rig", csv: PathLike, **options: Any) -> Report:
    """``rig discover`` on ``rig`` (a :class:`Rig`): the same as ``rig.discover(csv,
    **options)``; see :meth:`Rig.discover`."""
    return rig.discover(csv, **options)


def compare(
    measured: PathLike,
    model: Optional[PathLike] = None,
    rig: Optional[PathLike] = None,
    seed: int = 1,
) -> Report:
    """The simulation-versus-measurement gap (``rig compare --json``): the measured sweep
    (a CSV path) replayed on the virtual rig with the base model (``rig``, default the
    paper's or ``model``'s rig) and, with ``model``, a fitted rig file (``rig explain
    --write-model``). Keys: ``gap_rmse_base_a``, ``gap_rmse_model_a``, ``rows``, ..."""
    return _report(
        _native.compare(
            os.fspath(measured),
            None if model is None else os.fspath(model),
            None if rig is None else os.fspath(rig),
            int(seed),
        )
    )
