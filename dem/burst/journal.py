"""The burst's records for a resume (``dem.burst``): a staircase's journal (``_Journal``: its
relaxations, holds and probes as they finish, and the states it starts holds from) and the
command's checkpoint of the finished paths (``checkpoint_header``, ``read_checkpoint``:
DIR/burst_runs.jsonl)."""
from __future__ import annotations

import json
import os

import numpy as np

from .runs import HoldResult, ProbeResult, RelaxResult


class _Journal:
    """A staircase's record (``staircase``): ``dir``/R{r}_f{f}.jsonl, one line per relaxation and
    hold as it finishes, and the states it starts holds from (``keep``, ``state``) as npz files
    beside it, so that a resumed staircase replays what it had and goes on from its last
    equilibrium. ``Journal(None)``: records nothing (a staircase in memory)."""

    def __init__(self, base, resume=False):
        self.base = base
        self.records = []
        self.mem = {}
        if base and resume and os.path.exists(base + ".jsonl"):
            with open(base + ".jsonl") as f:
                for line in f.read().split("\n"):
                    try:
                        self.records.append(json.loads(line))
                    except ValueError:
                        continue
        if base:
            from common.io import atomic_write_bytes
            atomic_write_bytes(base + ".jsonl", "".join(json.dumps(r) + "\n"
                                                         for r in self.records).encode())

    def _add(self, rec):
        self.records.append(rec)
        if self.base:
            with open(self.base + ".jsonl", "a") as f:
                f.write(json.dumps(rec) + "\n")
                f.flush()
                os.fsync(f.fileno())

    def relaxation(self, name):
        for r in self.records:
            if r["kind"] == "relax" and r["name"] == name:
                return RelaxResult(self.state("relaxed_" + name), r["outcome"], r["steps"],
                                   r["c_loaded"], r["c_rest"], r["eta_rest"], r["ke_end"],
                                   r["unbalanced_end"], np.asarray(r["history"], float),
                                   r["wall_time"])
        return None

    def add_relaxation(self, name, res, c_path):
        self.keep("relaxed_" + name, res.state)
        self._add({"kind": "relax", "name": name, "outcome": res.outcome, "steps": res.steps,
                   "c_loaded": res.c_loaded, "c_rest": res.c_rest, "eta_rest": res.eta_rest,
                   "ke_end": res.ke_end, "unbalanced_end": res.unbalanced_end,
                   "history": res.history.tolist(), "wall_time": res.wall_time,
                   "c_path": c_path})

    def hold(self, k):
        for r in self.records:
            if r["kind"] == "hold" and r["k"] == k:
                return HoldResult(r["outcome"], r["steps"], np.asarray(r["history"], float),
                                  r["creep_rate"], r["wall_time"], r["hold"], r["ke_switch"],
                                  r["g_held"], r["wall_mass"], None, None, r["onset_step"])
        return None

    def probe(self, key):
        for r in self.records:
            if r["kind"] == "probe" and r["key"] == key:
                return ProbeResult(**{f: r[f] for f in ProbeResult._fields if f in r})
        return None

    def add_probe(self, p: ProbeResult):
        self._add({"kind": "probe", **p._asdict()})

    def add_hold(self, k, role, c_from, target, h, start):
        self._add({"kind": "hold", "k": k, "role": role, "c_from": c_from, "c_target": target,
                   "from": start,
                   "outcome": h.outcome, "steps": h.steps, "history": h.history.tolist(),
                   "creep_rate": h.creep_rate, "wall_time": h.wall_time, "hold": h.hold,
                   "ke_switch": h.ke_switch, "g_held": h.g_held, "wall_mass": h.wall_mass,
                   "onset_step": h.onset_step})

    def keep(self, key, state):
        if state is None:
            return
        self.mem[key] = state
        if self.base:
            from ..io import save_state
            save_state(f"{self.base}_{key}.npz", state)

    def state(self, key):
        if key in self.mem:
            return self.mem[key]
        from ..io import load_state
        return load_state(f"{self.base}_{key}.npz")[0]

    def has(self, key):
        return key in self.mem or bool(self.base) and os.path.exists(f"{self.base}_{key}.npz")

    def files(self):
        """The journal and its state files."""
        if not self.base:
            return []
        d, b = os.path.split(self.base)
        return [os.path.join(d, f) for f in os.listdir(d) if f.startswith(b + "_") or
                f == b + ".jsonl"]


def checkpoint_header(starts, ratios, opts) -> dict:
    """What a burst run is, for its checkpoint: the start states' fingerprints, the ratios and
    the options (``starts`` as ``load_starts`` gives them)."""
    from ..probes import state_fingerprint
    return json.loads(json.dumps({"fingerprints": {f"{f:g}": state_fingerprint(st)
                                                   for f, st, _ in starts},
                                  "ratios": [float(r) for r in ratios],
                                  "options": opts._asdict()}))


def read_checkpoint(out_dir, header) -> list:
    """The finished paths of ``out_dir``/burst_runs.jsonl (none if there is no such file; a torn
    last line dropped). ValueError (``--resume``, one line) if it belongs to other start states,
    ratios or options."""
    path = os.path.join(out_dir, "burst_runs.jsonl")
    if not os.path.exists(path):
        return []
    recs = []
    with open(path) as f:
        for line in f.read().split("\n"):
            try:
                recs.append(json.loads(line))
            except ValueError:
                continue
    if not recs or recs[0] != header:
        raise ValueError(f"--resume: {path} belongs to other start states, ratios or options; "
                         "remove it or choose another output folder")
    return recs[1:]
