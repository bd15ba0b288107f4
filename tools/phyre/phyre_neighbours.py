#!/usr/bin/env python
"""How fragile are PHYRE's own solutions? For every SOLVED pair of a balanced outcome set
(`phyre_gen.py outcomes` JSON Lines, plain), ask PHYRE 0.2.2 for the status of the same action with the
ball moved by one pixel (x +-1/255, y +-1/255; PHYRE quantises the centre to whole pixels) and write one
JSON line per pair: {"pair_id", "task_id", "neighbours": [4 status names or "OUT"]}.

  /work/venvs/phyre39/bin/python tools/phyre/phyre_neighbours.py balanced_tune.jsonl neighbours.jsonl

docs/fidelity.md ("Where trajectories part: PHYRE") relates these counts to annotrace's agreement.
"""
import json
import sys

import phyre


def main(src, dst):
    recs = [json.loads(line) for line in open(src) if line.strip()]
    ids = sorted({r['task_id'] for r in recs})
    sim = phyre.initialize_simulator(ids, 'ball')
    index = {t: i for i, t in enumerate(sim.task_ids)}
    with open(dst, 'w') as out:
        for r in recs:
            if r['status'] != 'SOLVED':
                continue
            x, y, rad = r['action']
            res = []
            for dx, dy in [(1, 0), (-1, 0), (0, 1), (0, -1)]:
                a = [x + dx / 255.0, y + dy / 255.0, rad]
                if not all(0 <= v <= 1 for v in a):
                    res.append('OUT')
                    continue
                res.append(sim.simulate_action(index[r['task_id']], a, need_images=False).status.name)
            out.write(json.dumps({'pair_id': r['pair_id'], 'task_id': r['task_id'], 'neighbours': res}) + '\n')


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2])
