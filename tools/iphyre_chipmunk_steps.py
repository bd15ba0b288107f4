#!/usr/bin/env python3
"""Dump one I-PHYRE episode of the original (iphyre 0.2.3 on pymunk 6.11.1) as a step-by-step scene for
`cargo run -p chipmunk-step --example replay`: the space as iphyre builds it (bodies, shapes,
constraints), the clicks that removed a block (as "remove before step k"), and after every step each
body's exact state and the order in which Chipmunk solved the contacts (the order of its arbiter list,
observed through the default collision handler's pre-solve callback, which Chipmunk calls for each
arbiter just before appending it to that list; returning True leaves the physics unchanged).

Run it with the original's interpreter:

    /work/venvs/iphyre/bin/python tools/iphyre_chipmunk_steps.py seesaw '[[455,320,4.8]]' 60 > /tmp/s.txt
    cargo run -p chipmunk-step --example replay -- /tmp/s.txt
    # or every N-th pair of a balanced set, both frame rates, one file per episode:
    /work/venvs/iphyre/bin/python tools/iphyre_chipmunk_steps.py --set tests/data/iphyre/balanced_tune.jsonl.gz \
        --every 4 --out /tmp/scenes

Output (one record per line, numbers in Python's repr, i.e. exact):
    space GX GY ITERATIONS DT
    body INDEX dynamic|static MASS MOMENT PX PY ANGLE
    circle BODY R FRICTION ELASTICITY
    segment BODY AX AY BX BY R FRICTION ELASTICITY
    pin A B
    spring A B REST STIFFNESS DAMPING
    remove STEP BODY               (body removed, with its shape and constraints, before step STEP)
    state STEP BODY PX PY ANGLE VX VY W
    arbiters STEP A:B:N A:B:N ...   (solver order; A, B the bodies of the first and second shape, N points)
    contact STEP A B NX NY [P1X P1Y P2X P2Y]...   (each arbiter's normal and points on shape a and b)
    result SUCCESS STEPS

With --compact (the test recordings in crates/chipmunk-step/tests/data/): no arbiters or contact lines,
state lines for the last step only, and every 30 steps and at the last one
    digest STEP HEX    (64-bit FNV-1a over every step so far: per body, in space order, its index as a
                        little-endian u64 and PX PY ANGLE VX VY W as little-endian f64; then the
                        step's arbiter order as written above, without "arbiters STEP ")
"""
import json
import os
import struct
import sys

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import pymunk  # noqa: E402
from iphyre.simulator import IPHYRE  # noqa: E402


FNV_OFFSET, FNV_PRIME, MASK = 0xCBF29CE484222325, 0x100000001B3, (1 << 64) - 1


def fnv(h, data):
    """64-bit FNV-1a over `data`, continuing from `h`."""
    for byte in data:
        h = ((h ^ byte) * FNV_PRIME) & MASK
    return h


def dump(game, clicks, fps, out, compact=False):
    env = IPHYRE(game, fps=fps)
    env.reset()
    space = env.space
    bodies = list(space.bodies)
    index = {b: i for i, b in enumerate(bodies)}
    out(f"space {space.gravity.x!r} {space.gravity.y!r} {space.iterations} {env.timestep!r}\n")
    for i, b in enumerate(bodies):
        kind = "static" if b.body_type == pymunk.Body.STATIC else "dynamic"
        mass = b.mass if kind == "dynamic" else 0.0
        moment = b.moment if kind == "dynamic" else 0.0
        out(f"body {i} {kind} {mass!r} {moment!r} {b.position.x!r} {b.position.y!r} {b.angle!r}\n")
        for s in b.shapes:
            if isinstance(s, pymunk.Circle):
                assert s.offset == (0, 0)
                out(f"circle {i} {s.radius!r} {s.friction!r} {s.elasticity!r}\n")
            else:
                out(f"segment {i} {s.a.x!r} {s.a.y!r} {s.b.x!r} {s.b.y!r} {s.radius!r} "
                    f"{s.friction!r} {s.elasticity!r}\n")
    for c in space.constraints:
        a, b = index[c.a], index[c.b]
        assert c.anchor_a == (0, 0) and c.anchor_b == (0, 0)
        if isinstance(c, pymunk.PinJoint):
            out(f"pin {a} {b}\n")
        else:
            out(f"spring {a} {b} {c.rest_length!r} {c.stiffness!r} {c.damping!r}\n")

    order, details = [], []

    def pre_solve(arb, _space, _data):
        sa, sb = arb.shapes
        cps = arb.contact_point_set
        order.append(f"{index[sa.body]}:{index[sb.body]}:{len(cps.points)}")
        pts = " ".join(f"{p.point_a.x!r} {p.point_a.y!r} {p.point_b.x!r} {p.point_b.y!r}" for p in cps.points)
        details.append(f"contact {step + 1} {index[sa.body]} {index[sb.body]} {cps.normal.x!r} {cps.normal.y!r} {pts}\n")
        return True

    space.add_default_collision_handler().pre_solve = pre_solve

    acts = sorted([list(a) for a in clicks], key=lambda a: a[-1])
    nxt, time_count, step = 0, 0, 0
    h = FNV_OFFSET
    while time_count < env.max_time:
        if nxt < len(acts):
            p, t = acts[nxt][0:2], acts[nxt][2]
            if time_count >= t:
                if t != 0:
                    before = list(space.bodies)
                    r = env.eliminate(p)
                    if r != -1:
                        out(f"remove {step + 1} {index[before[r]]}\n")
                nxt += 1
        order.clear()
        details.clear()
        space.step(env.timestep)
        time_count += env.timestep
        step += 1
        done = env.examine_success()
        last = done or not time_count < env.max_time
        for b in space.bodies:
            if b.body_type == pymunk.Body.STATIC:
                continue
            values = (b.position.x, b.position.y, b.angle, b.velocity.x, b.velocity.y, b.angular_velocity)
            h = fnv(h, struct.pack("<Q6d", index[b], *values))
            if not compact or last:
                out(f"state {step} {index[b]} " + " ".join(repr(v) for v in values) + "\n")
        h = fnv(h, " ".join(order).encode())
        if compact:
            if step % 30 == 0 or last:
                out(f"digest {step} {h:016x}\n")
        else:
            out(f"arbiters {step} {' '.join(order)}\n")
            out("".join(details))
        if done:
            out(f"result 1 {step}\n")
            return
    out(f"result 0 {step}\n")


def main():
    if sys.argv[1] == "--set":
        # --set FILE.jsonl[.gz] --every N --out DIR: one scene per N-th pair and fps, named PAIR_FPS.txt.
        import gzip
        path, every, out_dir = sys.argv[2], int(sys.argv[4]), sys.argv[6]
        os.makedirs(out_dir, exist_ok=True)
        opener = gzip.open if path.endswith(".gz") else open
        with opener(path, "rt") as f:
            records = [json.loads(line) for line in f if line.strip()]
        for rec in records[::every]:
            for res in rec["results"]:
                name = f"{out_dir}/{rec['pair_id']:04d}_{rec['game']}_{res['fps']}.txt"
                with open(name, "w") as f:
                    dump(rec["game"], rec["actions"], float(res["fps"]), f.write)
    else:
        args = [a for a in sys.argv[1:] if a != "--compact"]
        fps = float(args[2]) if len(args) > 2 else 60.0
        dump(args[0], json.loads(args[1]), fps, sys.stdout.write, compact="--compact" in sys.argv)


if __name__ == "__main__":
    main()
