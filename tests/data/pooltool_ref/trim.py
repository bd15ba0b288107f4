#!/usr/bin/env python3
"""Trim pooltool-trace/1 files (tools/pooltool/gen_traces.py --n 120 --seed 12345) to what
tests/replay.rs needs: meta (without the resolver blob), table, ball_ids, initial, events,
the last history entry per ball, and every 25th timestep plus the last one.

usage: trim.py SRC_DIR DST_DIR shot_005 shot_006 ...
"""
import json, sys, os

src, dst, names = sys.argv[1], sys.argv[2], sys.argv[3:]
for n in names:
    d = json.load(open(os.path.join(src, n + ".json")))
    d["meta"].pop("resolver", None)
    d["history"] = {k: [v[-1]] for k, v in d["history"].items()}
    ts = d["timesteps"]
    d["timesteps"] = [t for i, t in enumerate(ts) if i % 25 == 0 or i == len(ts) - 1]
    json.dump(d, open(os.path.join(dst, n + ".json"), "w"), separators=(",", ":"))
