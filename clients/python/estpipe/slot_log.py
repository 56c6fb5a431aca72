"""Reads a slot log in the replay format (docs/replay.md) exactly as `ipc-runner replay` does.

Rule for rule the reading of `ipc-runner/src/slot_log.rs` (`read_slots_within`), so that a log
published with `examples/publish_slots.py` gives the runner what replay steps:

- columns found by name, each used column once; `flags` optional (0);
- `k` >= 1, in increasing order; `node` < nodes; `delivered` is `0`, `1`, `false` or `true`;
  a `(k, node)` given twice is refused naming both lines;
- an undelivered row flagged lost (`FLAG_IPC_LOST` or `FLAG_NET_LOST`), a node missing from an instant and a whole missing
  instant are *lost* (never received: no information), not dropped by the channel;
- `tokens` (optional) is the bucket level a delivered row reported (docs/wire.md, "The bucket
  level on a delivered packet"): read only when delivered and not empty, else None;
- `late_after` (optional, 0 or empty: on time) marks a slot that reached the runner after its
  instant was handed on: replay steps it as lost at its instant and folds it in with `--lag`;
  here it is lost at its instant and, when `late` is a list, also appended to it as
  `(late_after, k, node, flags, y, tokens)` (a publisher cannot make the runner see it late);
- a line is at most 64 KiB, the file at most `2 * max_instants * nodes + 1` lines, and the
  last k at most `max_instants` (every k from 1 to the last is held in memory).

Every refusal is a `ValueError` whose message names the file, the line and the field
(`log.csv line 4: k: k = 3 after k = 7`), never a bare traceback.
"""

from .wire import FLAG_IPC_LOST, FLAG_NET_LOST, MAX_NODES, MAX_NY

FLAGS_LOST = FLAG_IPC_LOST | FLAG_NET_LOST

# The states of one node's slot of one instant.
DELIVERED = "delivered"
DROPPED = "dropped"  # dropped by the channel: sent, with delivered = 0
LOST = "lost"  # never received: not sent on the wire (a gap in the node's seq)

# ipc-runner's limits (ipc-runner/src/limits.rs, slot_log.rs): the longest line, and the
# instants the default --max-memory of replay holds.
MAX_LINE_BYTES = 64 * 1024
DEFAULT_MAX_INSTANTS = 5_000_000

U32_MAX = (1 << 32) - 1


def _parse_uint(text: str, bits: int):
    """A decimal unsigned integer of at most `bits` bits, as Rust's `str::parse` reads it."""
    t = text[1:] if text.startswith("+") else text
    if not t or not t.isascii() or not t.isdigit():
        raise ValueError("invalid digit found in string" if t else "cannot parse integer from empty string")
    v = int(t)
    if v >= 1 << bits:
        raise ValueError("number too large to fit in target type")
    return v


def _parse_float(text: str) -> float:
    """A float as Rust's `f64::from_str` reads it (`nan`, `inf`, exponents; no `_`)."""
    if "_" in text or not text or not text.isascii():
        raise ValueError("invalid float literal")
    try:
        return float(text)
    except ValueError:
        raise ValueError("invalid float literal") from None


def _lines(f, name: str, max_lines: int):
    """(line number, text) of each line, bounded in length and count as replay bounds them."""
    ln = 0
    while True:
        raw = f.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return
        ln += 1
        if ln > max_lines:
            raise ValueError(
                f"{name} line {ln}: more than {max_lines} lines (2 per instant and node of "
                f"the memory budget, plus the header)"
            )
        if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
            raise ValueError(f"{name} line {ln}: longer than {MAX_LINE_BYTES} bytes")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as e:
            raise ValueError(f"{name} line {ln}: not UTF-8 ({e.reason} at byte {e.start})") from None
        yield ln, text.rstrip("\n").rstrip("\r")


def read_slots(
    path: str, nodes: int, ny: list, max_instants: int = DEFAULT_MAX_INSTANTS, late: list = None
) -> list:
    """[(k, [(state, flags, y, tokens) for each node])] for every k from 1 to the last one.

    `state` is DELIVERED, DROPPED or LOST; `y` has MAX_NY entries (zeros where not delivered);
    `tokens` is the reported bucket level or None. Late rows go to `late` (module docs).
    """
    if not 1 <= nodes <= MAX_NODES or len(ny) < nodes or any(not 0 <= n <= MAX_NY for n in ny):
        raise ValueError(f"{path}: header shape outside the wire limits (nodes {nodes}, ny {ny})")
    name = str(path)
    max_lines = 2 * max_instants * nodes + 1
    try:
        f = open(path, "rb")
    except OSError as e:
        raise ValueError(f"{name}: cannot open ({e.strerror})") from None
    with f:
        lines = _lines(f, name, max_lines)
        first = next(lines, None)
        if first is None:
            raise ValueError(f"{name}: empty slot log (no header line)")
        cols = [c.strip() for c in first[1].split(",")]

        def find(c):
            at = [i for i, h in enumerate(cols) if h == c]
            if len(at) > 1:
                raise ValueError(
                    f"{name} line 1: column {c!r} appears twice (columns {at[0] + 1} and {at[1] + 1})"
                )
            return at[0] if at else None

        def idx(c):
            i = find(c)
            if i is None:
                raise ValueError(f"{name} line 1: header lacks column {c!r} (have {cols[:24]})")
            return i

        ck, cn, cd, cf = idx("k"), idx("node"), idx("delivered"), find("flags")
        ct, cl = find("tokens"), find("late_after")
        cy = [idx(f"y_{j}") for j in range(max(ny[:nodes], default=0))]
        instants = []  # [(k, {node: (state, flags, y)})], increasing k
        seen = {}  # node -> line of its row in the current instant
        for ln, line in lines:
            if not line.strip():
                continue
            cells = [c.strip() for c in line.split(",")]

            def get(c):
                return cells[c] if c < len(cells) else ""

            def bad(field, why):
                return ValueError(f"{name} line {ln}: {field}: {why}")

            try:
                k = _parse_uint(get(ck), 32)
            except ValueError as e:
                raise bad("k", f"{get(ck)!r} is not an instant ({e})") from None
            try:
                node = _parse_uint(get(cn), 64)
            except ValueError as e:
                raise bad("node", f"{get(cn)!r} is not a node ({e})") from None
            d = get(cd)
            if d in ("1", "true"):
                delivered = True
            elif d in ("0", "false"):
                delivered = False
            else:
                raise bad("delivered", f"must be 0 or 1, got {d!r}")
            flags = 0
            if cf is not None and get(cf):
                try:
                    flags = _parse_uint(get(cf), 32)
                except ValueError as e:
                    raise bad("flags", f"{get(cf)!r} ({e})") from None
            tokens = None
            if ct is not None and delivered and get(ct):
                try:
                    tokens = _parse_uint(get(ct), 32)
                except ValueError as e:
                    raise bad("tokens", f"{get(ct)!r} ({e})") from None
            if k == 0:
                raise bad("k", "k must be ≥ 1 (k = 0 is the prior)")
            late_after = 0
            if cl is not None and get(cl):
                try:
                    late_after = _parse_uint(get(cl), 32)
                except ValueError as e:
                    raise bad("late_after", f"{get(cl)!r} ({e})") from None
            if late_after != 0 and late_after < k:
                raise bad("late_after", f"{late_after} is before the slot's own instant k = {k}")
            if node >= nodes:
                raise bad("node", f"node {node} but the scenario has {nodes} node(s)")
            last = instants[-1][0] if instants else 0
            if k < last:
                raise bad("k", f"k = {k} after k = {last}; rows must be in increasing k")
            if k > max_instants:
                raise bad(
                    "k",
                    f"k = {k} means replaying {k} instants (every k from 1, gaps as lost); "
                    f"the budget holds {max_instants} instants",
                )
            if k > last:
                seen = {}
                instants.append((k, {}))
            if node in seen:
                raise bad(
                    "node",
                    f"(k = {k}, node {node}) again; line {seen[node]} has it already",
                )
            seen[node] = ln
            y = [0.0] * MAX_NY
            if delivered:
                # Every y column the reader uses is parsed, as replay does (the spec's largest ny).
                for j in range(len(cy)):
                    try:
                        y[j] = _parse_float(get(cy[j]))
                    except ValueError as e:
                        raise bad(f"y_{j}", f"{get(cy[j])!r} ({e})") from None
            # As the estimators read an observation (estimators/src/slots.rs): a
            # delivered row's measurement is used whatever its flags; an undelivered one is
            # lost when flagged lost (in the IPC or on the network), else a channel dropout.
            if delivered:
                state = DELIVERED
                y[ny[node]:] = [0.0] * (MAX_NY - ny[node])
            elif flags & FLAGS_LOST:
                state = LOST
            else:
                state = DROPPED
            entry = (state, flags, y if delivered else [0.0] * MAX_NY, tokens)
            if late_after:
                # Lost at its instant, as replay steps it before its fold.
                if late is not None:
                    late.append((late_after, k, node) + entry[1:])
                continue
            instants[-1][1][node] = entry
    lost = (LOST, FLAG_IPC_LOST, [0.0] * MAX_NY, None)
    out = []
    at = 0
    last = instants[-1][0] if instants else 0
    for k in range(1, last + 1):
        if at < len(instants) and instants[at][0] == k:
            row = instants[at][1]
            at += 1
        else:
            row = {}
        out.append((k, [row.get(m, lost) for m in range(nodes)]))
    return out
