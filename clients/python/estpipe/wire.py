"""The pipeline's wire contract (docs/wire.md) as ctypes structures over the iceoryx2 PyPI package.

The layouts are the Rust crate estpipe-wire's (`#[repr(C)]`); tests/pipeline_python.rs checks
every offset and size against it. iceoryx2 compares the type name, size and alignment of
payload and user header when a service is opened, so these must match exactly.
"""

import ctypes
import time

import iceoryx2 as iox2

WIRE_VERSION = 6

MAX_NX = 8
MAX_NY = 4
MAX_NODES = 8
COV_LEN = MAX_NX * (MAX_NX + 1) // 2

SLOT_DATA = 0
SLOT_END = 1
SLOT_ABORT = 2

FLAG_TRIGGERED = 1 << 0
FLAG_TOKEN_BLOCKED = 1 << 1
FLAG_CENSORED = 1 << 2
FLAG_RANDOM_LOSS = 1 << 3
FLAG_OCCLUDED = 1 << 4
FLAG_TOKENS = 1 << 5
FLAG_NET_LOST = 1 << 30
FLAG_IPC_LOST = 1 << 31

STATUS_OK = 0
STATUS_REFUSED = 1
STATUS_NONE_YET = 2

COV_NONE = 0
COV_ESTIMATE = 1
COV_BOUND = 2

DEFAULT_PREFIX = "estpipe"
READY_EVENT = 1
MAX_SUBSCRIBER_BUFFER = 4096
ESTIMATE_HISTORY = 16


_INT_RANGES = {
    ctypes.c_uint8: (0, (1 << 8) - 1),
    ctypes.c_uint16: (0, (1 << 16) - 1),
    ctypes.c_uint32: (0, (1 << 32) - 1),
    ctypes.c_uint64: (0, (1 << 64) - 1),
}


class Checked(ctypes.Structure):
    """A ctypes structure that refuses an out-of-range integer instead of wrapping it.

    ctypes stores `flags = -1` as 0xffffffff and `nodes = 257` as 1 without a word; here every
    integer field (keyword arguments included) raises `ValueError` naming the structure, the
    field, the value and its range, and a non-integer raises `TypeError`. Array fields are
    plain ctypes arrays: write them through the structure's helpers or check them yourself.
    """

    def __init__(self, **fields):
        super().__init__()
        for name, value in fields.items():
            setattr(self, name, value)

    def __setattr__(self, name, value):
        ctype = dict(self._fields_).get(name)
        bounds = _INT_RANGES.get(ctype)
        if bounds is not None:
            if isinstance(value, bool) or not isinstance(value, int):
                raise TypeError(
                    f"{type(self).__name__}.{name}: {value!r} is not an integer"
                )
            lo, hi = bounds
            if not lo <= value <= hi:
                raise ValueError(
                    f"{type(self).__name__}.{name}: {value} is outside {lo}..={hi}"
                )
        elif ctype is None and not name.startswith("_"):
            raise AttributeError(f"{type(self).__name__} has no field {name!r}")
        super().__setattr__(name, value)


def _in_range(what: str, value, lo: int, hi: int) -> int:
    """`value` as an int in lo..=hi, else `ValueError` naming `what`."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{what}: {value!r} is not an integer")
    if not lo <= value <= hi:
        raise ValueError(f"{what}: {value} is outside {lo}..={hi}")
    return value


class Slot(Checked):
    """One sensor node's observation of one sampling instant (payload of <prefix>/slots)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("kind", ctypes.c_uint32),
        ("stream_id", ctypes.c_uint64),
        ("seq", ctypes.c_uint64),
        ("k", ctypes.c_uint32),
        ("node", ctypes.c_uint8),
        ("nodes", ctypes.c_uint8),
        ("ny", ctypes.c_uint8),
        ("delivered", ctypes.c_uint8),
        ("flags", ctypes.c_uint32),
        ("tokens", ctypes.c_uint32),
        ("send_ns", ctypes.c_uint64),
        ("period_ns", ctypes.c_uint64),
        ("stream_start_ns", ctypes.c_uint64),
        ("y", ctypes.c_double * MAX_NY),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name both sides use."""
        return "estpipe::wire::Slot"


class StreamHeader(Checked):
    """The stream's shape: the iceoryx2 user header of every slot."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("nodes", ctypes.c_uint8),
        ("nx", ctypes.c_uint8),
        ("reserved", ctypes.c_uint16),
        ("ny", ctypes.c_uint8 * MAX_NODES),
        ("model", ctypes.c_uint64),
        ("scenario", ctypes.c_uint8 * 32),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name both sides use."""
        return "estpipe::wire::StreamHeader"

    @classmethod
    def from_json(cls, h: dict) -> "StreamHeader":
        """The header `ipc-runner stream-header` prints (a dict parsed from its JSON).

        Checked as the runner checks a header (docs/wire.md, StreamHeader): `ValueError`
        naming the field for a missing key, another wire version, `nodes` or `nx` outside
        1..=8, `ny` not one entry 0..=4 per node, a model that is not a 64-bit hex string,
        a name over 32 bytes.
        """
        if not isinstance(h, dict):
            raise ValueError(f"stream header: expected a JSON object, got {type(h).__name__}")
        for key in ("wire_version", "nodes", "nx", "ny", "model", "scenario"):
            if key not in h:
                raise ValueError(f"stream header: missing {key!r}")
        version = _in_range("stream header: wire_version", h["wire_version"], 0, (1 << 32) - 1)
        if version != WIRE_VERSION:
            raise ValueError(
                f"stream header: wire_version {version}, but this client speaks {WIRE_VERSION}"
            )
        nodes = _in_range("stream header: nodes", h["nodes"], 1, MAX_NODES)
        nx = _in_range("stream header: nx", h["nx"], 1, MAX_NX)
        ny = h["ny"]
        if not isinstance(ny, list) or len(ny) != nodes:
            raise ValueError(f"stream header: ny must list {nodes} entries, got {ny!r}")
        model = h["model"]
        if not isinstance(model, str) or not model.startswith("0x"):
            raise ValueError(f"stream header: model {model!r} is not a 0x… hex string")
        try:
            model = int(model, 16)
        except ValueError:
            raise ValueError(f"stream header: model {h['model']!r} is not hex") from None
        model = _in_range("stream header: model", model, 0, (1 << 64) - 1)
        if not isinstance(h["scenario"], str):
            raise ValueError("stream header: scenario must be a string")
        name = h["scenario"].encode()
        if len(name) > 32:
            raise ValueError(f"stream header: scenario name is {len(name)} bytes, at most 32")
        out = cls(version=version, nodes=nodes, nx=nx, model=model)
        for m, n in enumerate(ny):
            out.ny[m] = _in_range(f"stream header: ny[{m}]", n, 0, MAX_NY)
        ctypes.memmove(out.scenario, name, len(name))
        return out


class Estimate(Checked):
    """One estimator's estimate (payload of <prefix>/estimates)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("k", ctypes.c_uint32),
        ("stream_id", ctypes.c_uint64),
        ("seq", ctypes.c_uint64),
        ("estimator", ctypes.c_uint32),
        ("nx", ctypes.c_uint32),
        ("name", ctypes.c_uint8 * 16),
        ("status", ctypes.c_uint32),
        ("cov_kind", ctypes.c_uint32),
        ("x", ctypes.c_double * MAX_NX),
        ("p", ctypes.c_double * COV_LEN),
        ("slot_send_ns", ctypes.c_uint64),
        ("receive_ns", ctypes.c_uint64),
        ("step_done_ns", ctypes.c_uint64),
        ("late_folded", ctypes.c_uint32),
        ("revised_from", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name both sides use."""
        return "estpipe::wire::Estimate"

    def estimator_name(self) -> str:
        """The estimator's name."""
        return bytes(self.name).split(b"\0", 1)[0].decode(errors="replace")

    def xhat(self) -> list:
        """x̂_k (nx entries)."""
        return list(self.x[: self.nx])

    def covariance(self) -> list:
        """P_k as nx rows of nx (from the packed upper triangle)."""
        n = self.nx
        return [[self.p[packed_index(n, i, j)] for j in range(n)] for i in range(n)]


class Truth(Checked):
    """The true state (payload of <prefix>/truth, evaluation only)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("k", ctypes.c_uint32),
        ("stream_id", ctypes.c_uint64),
        ("nx", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
        ("x", ctypes.c_double * MAX_NX),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name both sides use."""
        return "estpipe::wire::Truth"


def packed_index(nx: int, i: int, j: int) -> int:
    """Index of P[i][j] in Estimate.p: the upper triangle row by row."""
    i, j = min(i, j), max(i, j)
    return i * nx - i * (i - 1) // 2 + (j - i)


def seq_of(k: int) -> int:
    """A node's sequence number of its slot of instant k: k - 1 (every node is its own
    stream, since wire version 3)."""
    return max(k - 1, 0)


def monotonic_ns() -> int:
    """CLOCK_MONOTONIC in ns, the clock of every timestamp on the wire."""
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


def service_name(prefix: str, what: str):
    """The iceoryx2 name of service <prefix>/<what>."""
    return iox2.ServiceName.new(f"{prefix}/{what}")


def slot_service(node, prefix: str):
    """Opens (or creates) <prefix>/slots with the contract's QoS."""
    return (
        node.service_builder(service_name(prefix, "slots"))
        .publish_subscribe(Slot)
        .user_header(StreamHeader)
        .max_publishers(MAX_NODES)
        .max_subscribers(4)
        .subscriber_max_buffer_size(MAX_SUBSCRIBER_BUFFER)
        .history_size(0)
        .enable_safe_overflow(False)
        .open_or_create()
    )


def ready_event_service(node, prefix: str):
    """Opens (or creates) <prefix>/slots-ready, notified with READY_EVENT per instant."""
    return (
        node.service_builder(service_name(prefix, "slots-ready"))
        .event()
        .max_notifiers(MAX_NODES)
        .max_listeners(4)
        .open_or_create()
    )


def estimate_service(node, prefix: str):
    """Opens (or creates) <prefix>/estimates with the contract's QoS."""
    return (
        node.service_builder(service_name(prefix, "estimates"))
        .publish_subscribe(Estimate)
        .max_publishers(1)
        .max_subscribers(8)
        .subscriber_max_buffer_size(MAX_SUBSCRIBER_BUFFER)
        .history_size(ESTIMATE_HISTORY)
        .enable_safe_overflow(True)
        .open_or_create()
    )


def layouts() -> dict:
    """{type: {"size", "align", "fields": {name: [offset, size]}}} for the layout test."""
    out = {}
    for t in (Slot, StreamHeader, Estimate, Truth):
        fields = {
            name: [getattr(t, name).offset, getattr(t, name).size]
            for name, _ in t._fields_
        }
        out[t.__name__] = {
            "type_name": t.type_name(),
            "size": ctypes.sizeof(t),
            "align": ctypes.alignment(t),
            "fields": fields,
        }
    return out
