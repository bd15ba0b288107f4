#!/usr/bin/env bash
# The side-by-side throughput table: annotrace's `simulate` (command line to Parquet, `annotrace bench`)
# and the three original simulators (pooltool 0.6.0, PHYRE 0.2.2, I-PHYRE 0.2.3) measured on this
# machine in one session, with the bench's `annotate` case (the built-in billiards library over the
# billiards case's shots), written into docs/performance.md between the `side-by-side` markers.
#
#   tools/side_by_side.sh                 # scale 1: the issue's sizes (tens of minutes in a debug build)
#   SCALE=0.1 tools/side_by_side.sh       # a tenth of every annotrace case, fewer original episodes
#
# Environment variables:
#   SCALE          multiplies annotrace's case sizes (default 1) and the originals' episode counts
#   ANNOTRACE      the annotrace binary (default: target/debug/annotrace of $CARGO_TARGET_DIR or ./target,
#                  built with `cargo build --locked` when missing). For the throughput figures build
#                  `cargo build --locked --profile dist` and pass target/dist/annotrace (Cargo.toml, [profile.dist])
#   BUILD          the build named in the table, as given (default: the profile the binary reports,
#                  debug, release or dist: `annotrace bench` reads it from its build, see build.rs)
#   POOL_VENV      pooltool venv (default /work/venvs/pooltool if present, else tools/pooltool/venv, made
#                  with tools/pooltool/install.sh)
#   PHYRE_VENV     PHYRE venv, Python 3.9 (default /work/venvs/phyre39 if present, else tools/phyre/venv39,
#                  made with $PYTHON39 -m venv and `pip install phyre "numpy<1.24"`)
#   IPHYRE_VENV    I-PHYRE venv (default /work/venvs/iphyre if present, else tools/phyre/venv, made with
#                  `pip install iphyre numpy pygame "pymunk<7"`)
#   PYTHON39       interpreter for a new PHYRE venv (default python3.9, else pyenv's installed 3.9)
#   NO_DOCS=1      print the table without editing docs/performance.md
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
SCALE="${SCALE:-1}"
WORK="$(mktemp -d "${TMPDIR:-/tmp}/side-by-side.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT
export SDL_VIDEODRIVER=dummy PYGAME_HIDE_SUPPORT_PROMPT=1

pick() { # pick DEFAULT_IF_PRESENT FALLBACK
  if [ -x "$1/bin/python" ]; then echo "$1"; else echo "$2"; fi
}
POOL_VENV="${POOL_VENV:-$(pick /work/venvs/pooltool "$ROOT/tools/pooltool/venv")}"
PHYRE_VENV="${PHYRE_VENV:-$(pick /work/venvs/phyre39 "$ROOT/tools/phyre/venv39")}"
IPHYRE_VENV="${IPHYRE_VENV:-$(pick /work/venvs/iphyre "$ROOT/tools/phyre/venv")}"

# --- venvs (the recipes of tools/pooltool/install.sh and tools/phyre/README.md) ---
if [ ! -x "$POOL_VENV/bin/python" ]; then
  echo "== installing pooltool 0.6.0 into $POOL_VENV" >&2
  VENV="$POOL_VENV" tools/pooltool/install.sh >&2
fi
if [ ! -x "$PHYRE_VENV/bin/python" ]; then
  echo "== installing PHYRE 0.2.2 into $PHYRE_VENV" >&2
  py39="${PYTHON39:-python3.9}"
  is39() { "$1" -c 'import sys; assert sys.version_info[:2] == (3, 9)' >/dev/null 2>&1; }
  # `command -v` is not enough: pyenv's shim for python3.9 exists where a 3.9 is installed but not
  # selected, and fails when run; then take pyenv's own 3.9 if it has one.
  if [ -z "${PYTHON39:-}" ] && ! is39 "$py39" && command -v pyenv >/dev/null; then
    for cand in "$(pyenv root)"/versions/3.9*/bin/python3.9; do
      if is39 "$cand"; then py39="$cand"; break; fi
    done
  fi
  is39 "$py39" || {
    echo "PHYRE needs Python 3.9 (no wheels for later versions): set PYTHON39 to a 3.9 interpreter (e.g. pyenv install 3.9.18)" >&2
    exit 2
  }
  "$py39" -m venv "$PHYRE_VENV"
  "$PHYRE_VENV/bin/pip" install phyre "numpy<1.24" >&2
fi
if [ ! -x "$IPHYRE_VENV/bin/python" ]; then
  echo "== installing I-PHYRE into $IPHYRE_VENV" >&2
  python3 -m venv "$IPHYRE_VENV"
  "$IPHYRE_VENV/bin/pip" install iphyre numpy pygame "pymunk<7" >&2
fi

# --- annotrace ---
if [ -z "${ANNOTRACE:-}" ]; then
  ANNOTRACE="${CARGO_TARGET_DIR:-$ROOT/target}/debug/annotrace"
  if [ ! -x "$ANNOTRACE" ]; then
    cargo build --locked >&2
  fi
fi

n_of() { python3 -c "import sys; print(max(1, round($1 * float(sys.argv[1]))))" "$SCALE"; }

# --- annotrace, same session ---
echo "== annotrace bench --scale $SCALE --threads 1,2" >&2
"$ANNOTRACE" bench --scale "$SCALE" --threads 1,2 --dir "$WORK/bench" --json "$WORK/annotrace.jsonl" >"$WORK/annotrace.md"
# The episodes of the bench's PHYRE stride-6 case (its tasks and actions, kept in its run folder), for
# the original to simulate too: the same work on both sides, beside the original's own random set.
"$ANNOTRACE" -q query --run "$WORK/bench/phyre-6-t1" --format csv --out "$WORK/phyre-episodes.csv" \
  "select task_id, extra, success from traces order by trace_id"
rm -rf "$WORK/bench"

# --- the originals ---
echo "== pooltool 0.6.0: simulate + continuize(dt 0.01), bench.py" >&2
cp -r tools/pooltool "$WORK/pooltool"
POOL_N="$(n_of 200)"
"$POOL_VENV/bin/python" "$WORK/pooltool/bench.py" --phase main --n "$POOL_N" --seed 777 >"$WORK/pooltool.log" 2>&1
cp "$WORK/pooltool/bench_results/main.json" "$WORK/pooltool.json"

echo "== PHYRE 0.2.2: simulate_action, status only, featurised objects every step, images every 60" >&2
PHYRE_N="$(n_of 500)"
(cd tools/phyre && "$PHYRE_VENV/bin/python" - "$PHYRE_N" "$WORK/phyre-episodes.csv" >"$WORK/phyre.log" 2>&1) <<'EOF'
# The modes of phyre_traces.py speed that the table compares (status only; featurised objects every
# step; images every 60 steps), on the first tasks of the ball tier's templates, round-robin, one valid
# random action each (the images-every-step mode of that script is left out: it dominates its time).
# Then status only and featurised objects again on annotrace's episodes (argv[2]: task id, action and
# outcome per trace), the steps each set simulates, and how many outcomes agree with annotrace's.
import csv, json, sys, time
import numpy as np
import phyre
n = int(sys.argv[1])
_, _, test = phyre.get_fold('ball_within_template', 0)
by_template = {}
for t in sorted(test):
    by_template.setdefault(t.split(':')[0], []).append(t)
ids, k = [], 0
while len(ids) < n:
    for tpl in sorted(by_template):
        if k < len(by_template[tpl]) and len(ids) < n:
            ids.append(by_template[tpl][k])
    k += 1
sim = phyre.initialize_simulator(ids, 'ball')
rng = np.random.RandomState(0)
acts = []
for ti in range(len(ids)):
    while True:
        a = sim.sample(rng=rng)
        if sim.simulate_action(ti, a, need_images=False).status != phyre.SimulationStatus.INVALID_INPUT:
            acts.append(a)
            break
for label, kw in [('status only', dict(need_images=False)),
                  ('featurized objects stride 1', dict(need_images=False, need_featurized_objects=True, stride=1)),
                  ('images stride 60 (default)', dict(need_images=True))]:
    t0 = time.perf_counter()
    for ti, a in enumerate(acts):
        sim.simulate_action(ti, a, **kw)
    dt = time.perf_counter() - t0
    print(f'simulate_action [{label}]: {len(acts) / dt:.1f} episodes/s over {len(acts)}')
ours = list(csv.DictReader(open(sys.argv[2])))
ours_ids = [r['task_id'] for r in ours]
ours_acts = [np.array([json.loads(r['extra'])['action'][k] for k in 'xyr']) for r in ours]
sim2 = phyre.initialize_simulator(ours_ids, 'ball')
agree = 0
for ti, (a, r) in enumerate(zip(ours_acts, ours)):
    solved = sim2.simulate_action(ti, a, need_images=False).status == phyre.SimulationStatus.SOLVED
    agree += solved == (r['success'] == 'true')
print(f'outcomes agreeing with annotrace: {agree} of {len(ours)}')
for label, kw in [('status only', dict(need_images=False)),
                  ('featurized objects stride 1', dict(need_images=False, need_featurized_objects=True, stride=1))]:
    t0 = time.perf_counter()
    for ti, a in enumerate(ours_acts):
        sim2.simulate_action(ti, a, **kw)
    dt = time.perf_counter() - t0
    print(f'simulate_action [{label}, annotrace episodes]: {len(ours_acts) / dt:.1f} episodes/s over {len(ours_acts)}')
for label, s, aa in [('own set', sim, acts), ('annotrace episodes', sim2, ours_acts)]:
    steps = sum(len(s.simulate_action(ti, a, need_images=False, need_featurized_objects=True,
                                      stride=1).featurized_objects.features) for ti, a in enumerate(aa))
    print(f'steps [{label}]: {steps / len(aa):.1f} per episode over {len(aa)}')
EOF

echo "== I-PHYRE: simulate() at 60 fps and the trace recorder" >&2
IPHYRE_N="$(n_of 20)"
(cd tools/phyre && "$IPHYRE_VENV/bin/python" - "$IPHYRE_N" >"$WORK/iphyre.log" 2>&1) <<'EOF'
import random, sys, time
sys.path.insert(0, '.')
from iphyre.games import GAMES
from iphyre.simulator import IPHYRE
from iphyre_export import random_actions, Recorder
n = int(sys.argv[1])
rng = random.Random(1)
t0 = time.perf_counter(); eps = 0
for g in GAMES:
    env = IPHYRE(g, fps=60)
    for _ in range(n):
        acts = random_actions(env, rng)
        env.reset(); env.simulate([list(x) for x in acts]); eps += 1
dt = time.perf_counter() - t0
print(f"simulate60 {eps / dt:.2f} episodes/s over {eps}")
t0 = time.perf_counter(); eps = 0
for g in GAMES[::4]:
    env = IPHYRE(g); rec = Recorder(g)
    for _ in range(max(1, n // 4)):
        rec.run(random_actions(env, rng)); eps += 1
dt = time.perf_counter() - t0
print(f"recorder60 {eps / dt:.2f} episodes/s over {eps}")
EOF

# --- versions and machine ---
{
  echo "date=$(date -u +%Y-%m-%dT%H:%MZ)"
  echo "machine=$(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'), $(free -g | awk '/Mem:/{print $2}') GiB, $(uname -sr)"
  echo "load=$(cut -d' ' -f1-3 /proc/loadavg)"
  echo "annotrace=$("$ANNOTRACE" --version) ($(git rev-parse --short HEAD 2>/dev/null || echo '?'))"
  if [ -n "${BUILD:-}" ]; then echo "build=$BUILD"; fi
  echo "pooltool=$("$POOL_VENV/bin/python" -c 'import pooltool, sys; print(pooltool.__version__, "Python", sys.version.split()[0])' 2>/dev/null)"
  echo "phyre=$("$PHYRE_VENV/bin/pip" show phyre 2>/dev/null | awk '/^Version/{print $2}') Python $("$PHYRE_VENV/bin/python" -c 'import sys; print(sys.version.split()[0])')"
  echo "iphyre=$("$IPHYRE_VENV/bin/pip" show iphyre 2>/dev/null | awk '/^Version/{print $2}') pymunk $("$IPHYRE_VENV/bin/pip" show pymunk 2>/dev/null | awk '/^Version/{print $2}') Python $("$IPHYRE_VENV/bin/python" -c 'import sys; print(sys.version.split()[0])')"
} >"$WORK/env.txt"

python3 tools/side_by_side_table.py "$WORK" "$SCALE" >"$WORK/table.md"
cat "$WORK/table.md"
if [ "${NO_DOCS:-}" != 1 ]; then
  python3 tools/side_by_side_table.py --into docs/performance.md "$WORK/table.md"
  echo "== written into docs/performance.md" >&2
fi
