"""Reference outcomes from PHYRE 0.2.2 for annotrace's fidelity check (run with the py3.9 venv).

Writes JSON Lines: one (task, action) per line with PHYRE's status (1 SOLVED, -1 NOT_SOLVED, 0 INVALID_INPUT).
Per task: actions drawn uniformly from [0,1]^3 with np.random.RandomState(seed*100003 + task_index);
the first 4 draws are kept whatever their status (validity check), then draws continue until 4 valid
unsolved and up to 2 solved actions are kept (at most 400 valid draws)."""
import hashlib, json, sys
import numpy as np
import phyre

out, tasks_per_tpl, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
all_ids = sorted(phyre.metrics.get_task_ids_in_tier('ball'))
by_tpl = {}
for t in all_ids:
    by_tpl.setdefault(t.split(':')[0], []).append(t)
chosen = []
for tpl, ids in sorted(by_tpl.items()):
    ids = phyre.util.stable_shuffle(ids, f'annotrace_fidelity{seed}')
    chosen.extend(sorted(ids[:tasks_per_tpl]))
sim = phyre.initialize_simulator(chosen, 'ball')
rows = []
for i, tid in enumerate(chosen):
    rng = np.random.RandomState(seed * 100003 + i)
    kept_unsolved = kept_solved = draws = valid = 0
    while True:
        a = rng.uniform(size=3)
        draws += 1
        st = sim.simulate_action(i, a, need_images=False, need_featurized_objects=False).status
        s = int(st)
        keep = draws <= 4
        if s == 1 and kept_solved < 2:
            keep = True
        if s == -1 and kept_unsolved < 4:
            keep = True
        if keep:
            rows.append({'task_id': tid, 'action': [float(x) for x in a], 'status': s})
            kept_solved += s == 1
            kept_unsolved += s == -1
        valid += s != 0
        if (kept_unsolved >= 4 and kept_solved >= 2) or valid >= 400:
            break
    print(tid, draws, kept_solved, kept_unsolved, file=sys.stderr)
with open(out, 'w') as f:
    for r in rows:
        f.write(json.dumps(r) + '\n')
