"""Render the initial scene of the first task of each PHYRE ball-tier template as a 5x5 montage.

Each panel is the 256x256 initial scene (phyre.observations_to_uint8_rgb, y flipped so that
up is up) with the task id printed above it. This regenerates an equivalent of
the montage the template descriptions were written from: the scene pixels are identical, only the font of
the task-id labels may differ.

Usage (with the PHYRE Python 3.9 venv's python):
  python phyre_render_templates.py [OUT]   (default: phyre_ball_templates.png next to this script)
"""
import math
import pathlib
import sys

import phyre
import phyre.metrics
from PIL import Image, ImageDraw

COLS = 5
PAD = 4        # blank pixels right of and below each panel
LABEL_H = 15   # strip above each panel for the task id


def main():
    out = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else \
        pathlib.Path(__file__).resolve().parent / 'phyre_ball_templates.png'
    first = {}
    for tid in sorted(phyre.metrics.get_task_ids_in_tier('ball')):
        first.setdefault(tid.split(':')[0], tid)
    task_ids = [first[t] for t in sorted(first)]
    sim = phyre.initialize_simulator(task_ids, 'ball')
    size = 256
    cell_w, cell_h = size + PAD, LABEL_H + size + PAD
    rows = math.ceil(len(task_ids) / COLS)
    canvas = Image.new('RGB', (COLS * cell_w, rows * cell_h), 'white')
    draw = ImageDraw.Draw(canvas)
    for k, (tid, scene) in enumerate(zip(task_ids, sim.initial_scenes)):
        x0, y0 = (k % COLS) * cell_w, (k // COLS) * cell_h
        draw.text((x0 + 2, y0 + 2), tid, fill=(0, 0, 0))
        canvas.paste(Image.fromarray(phyre.observations_to_uint8_rgb(scene)), (x0, y0 + LABEL_H))
    canvas.save(out)
    print(f'wrote {out}: {len(task_ids)} templates: {", ".join(task_ids)}')


if __name__ == '__main__':
    main()
