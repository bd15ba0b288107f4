"""Outcomes of the original I-PHYRE (iphyre 0.2.3 on pymunk 6.11.1) for random (game, click list) pairs.

Writes the reference set that annotrace's I-PHYRE fidelity test (`tests/it/iphyre.rs`) compares against:
a JSON document with, per pair, the game, the clicks `[x, y, t]`, the frame rate, and the original's
outcome (`success`, effective eliminations, end time). Click sets are drawn in iphyre's
`utils.generate_actions` style: every eliminable block is clicked at its centre at a time from
{0.1, 0.2, ..., 6.9} s and skipped with probability 0.2.

Run it with a Python that has the original installed (outside the repository):
    python3.11 -m venv /work/iphyre-venv
    /work/iphyre-venv/bin/pip install iphyre numpy pygame "pymunk<7"
    /work/iphyre-venv/bin/python tools/iphyre_reference.py --per-game 6 --seed 0 --out tests/data/iphyre/reference.json
"""
import argparse
import json
import os
import random

os.environ.setdefault('SDL_VIDEODRIVER', 'dummy')
os.environ.setdefault('PYGAME_HIDE_SUPPORT_PROMPT', '1')

import pymunk  # noqa: E402
from iphyre.games import GAMES  # noqa: E402
from iphyre.simulator import IPHYRE  # noqa: E402


def random_clicks(env, rng):
    """One click set: each eliminable block centre at a time in {0.1..6.9} s, skipped with p = 0.2."""
    centres = [a for a in env.get_action_space()[1:] if a != [0., 0.]]
    clicks = []
    for x, y in centres:
        tenths = rng.randint(1, 69)
        if rng.random() < 0.2:
            continue
        clicks.append([float(x), float(y), tenths / 10])
    clicks.sort(key=lambda c: c[2])
    return clicks


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--per-game', type=int, default=6, help='click sets per game and frame rate')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--fps', default='60', help='comma-separated frame rates, e.g. 60,10')
    ap.add_argument('--out', required=True)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    pairs = []
    for fps in [int(f) for f in a.fps.split(',')]:
        for game in GAMES:
            env = IPHYRE(game, fps=fps)
            for _ in range(a.per_game):
                clicks = random_clicks(env, rng)
                env.reset()
                ok, valid, t = env.simulate([list(c) for c in clicks])
                pairs.append({'game': game, 'fps': fps, 'clicks': clicks, 'success': bool(ok),
                              'eliminations': int(valid), 'time': round(float(t), 6)})
    doc = {
        'source': 'tools/iphyre_reference.py',
        'simulator': {'iphyre': '0.2.3', 'pymunk': pymunk.version},
        'seed': a.seed,
        'per_game': a.per_game,
        'pairs': pairs,
    }
    with open(a.out, 'w') as f:
        json.dump(doc, f, separators=(',', ':'))
        f.write('\n')
    solved = sum(p['success'] for p in pairs)
    print(f'wrote {a.out}: {len(pairs)} pairs, {solved} solved by the original')


if __name__ == '__main__':
    main()
