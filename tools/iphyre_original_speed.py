"""CPU time of the original I-PHYRE over a balanced set's episodes, at 60 and 10 fps.

For each (game, actions) row of a balanced set (tests/data/iphyre/balanced_*.jsonl.gz) this runs the
original's `IPHYRE(game, fps=fps).reset(); simulate(actions)` once per fps and prints the episodes and
the process CPU seconds, to set beside `cargo run --example fidelity -- iphyre SET --set engine=E`
(docs/fidelity.md, "I-PHYRE on a Chipmunk-faithful step").

usage: VENV/bin/python tools/iphyre_original_speed.py tests/data/iphyre/balanced_tune.jsonl.gz
(VENV: a venv with `pip install iphyre numpy pygame "pymunk<7"`, as docs/fidelity.md sets up.)
"""
import gzip
import json
import os
import sys
import time

os.environ["SDL_VIDEODRIVER"] = "dummy"
from iphyre.simulator import IPHYRE  # noqa: E402

rows = [json.loads(line) for line in gzip.open(sys.argv[1], "rt")]
episodes = [
    (r["game"], r.get("actions") or r.get("clicks"), fps) for r in rows for fps in (60, 10)
]
t0 = time.process_time()
for game, actions, fps in episodes:
    env = IPHYRE(game, fps=fps)
    env.reset()
    env.simulate(actions)
print(len(episodes), "episodes", round(time.process_time() - t0, 2), "s CPU")
