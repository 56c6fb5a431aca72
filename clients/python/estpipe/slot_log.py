"""Reads a slot log in the replay format (docs/replay.md) as instants of slots."""

import csv

from .wire import MAX_NY


def read_slots(path: str, nodes: int, ny: list) -> list:
    """[(k, [(delivered, flags, y) for each node])] for every k from 1 to the last one.

    As `ipc-runner replay` reads it: a node missing from an instant, or a whole missing
    instant, is a dropped packet; the nodes of an instant may come in any order.
    """
    instants = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            k, node = int(row["k"]), int(row["node"])
            if k < 1 or not 0 <= node < nodes:
                raise ValueError(f"{path}: bad slot k = {k}, node = {node}")
            delivered = row["delivered"].strip() in ("1", "true")
            flags = int(row.get("flags") or 0)
            y = [0.0] * MAX_NY
            if delivered:
                for j in range(ny[node]):
                    y[j] = float(row[f"y_{j}"])
            instants.setdefault(k, {})[node] = (delivered, flags, y)
    last = max(instants, default=0)
    dropped = (False, 0, [0.0] * MAX_NY)
    return [
        (k, [instants.get(k, {}).get(m, dropped) for m in range(nodes)])
        for k in range(1, last + 1)
    ]
