#!/usr/bin/env python3
"""Writes the three small example traces in data/examples/ (one per environment).

The traces follow closed-form motion (constant deceleration, free fall) so that their numbers are
physically plausible and easy to check by hand; they are not output of the original simulators.
Run from anywhere: python3 data/examples/make_examples.py
"""
import json
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))
G = 9.81


def r(x, n=6):
    return round(x, n)


def pooltool():
    # The cue ball rolls up the table at 0.45 m/s into the stationary 1-ball (a straight-on hit).
    R, mu_r = 0.028575, 0.01
    dt = 0.1
    cue0, one = (0.4953, 0.3), (0.4953, 0.9)
    v0 = 0.45
    a = mu_r * G
    # time the cue ball centre reaches 2R before the 1-ball centre: y0 + v0 t - a t^2/2 = one_y - 2R
    d = one[1] - 2 * R - cue0[1]
    tc = (v0 - math.sqrt(v0 * v0 - 2 * a * d)) / a
    vc = v0 - a * tc
    # after a straight-on collision the cue ball stops sliding-free (idealised) and the 1-ball rolls on
    v1 = 0.95 * vc
    t_stop = tc + v1 / a
    steps, events = [], []
    t, k = 0.0, 0
    while t <= t_stop + 1e-9:
        if t < tc:
            cy, cv, cstate = cue0[1] + v0 * t - a * t * t / 2, v0 - a * t, "rolling"
            oy, ov, ostate = one[1], 0.0, "stationary"
        else:
            s = t - tc
            cy, cv, cstate = one[1] - 2 * R - 1e-6, 0.0, "stationary"
            oy, ov = one[1] + v1 * s - a * s * s / 2, max(v1 - a * s, 0.0)
            ostate = "rolling" if ov > 0 else "stationary"
        code = {"stationary": 0, "rolling": 3}
        balls = []
        for bid, y, v, st in (("cue", cy, cv, cstate), ("1", oy, ov, ostate)):
            balls.append({
                "kind": "ball", "ball_id": bid,
                "position": [cue0[0], r(y), R], "velocity": [0.0, r(v), 0.0],
                "angular_velocity": [r(-v / R), 0.0, 0.0],
                "motion_state_code": code[st], "motion_state": st, "radius": R,
            })
        steps.append({"index": k, "t": r(t), "objects": balls})
        k += 1
        t = k * dt
    events = [
        {"kind": "physics_stick_ball", "t": 0.0, "payload": {"agents": ["cue_stick", "cue"], "V0": v0, "phi": 90.0, "theta": 0.0, "a": 0.0, "b": 0.4}},
        {"kind": "physics_ball_ball", "t": r(tc), "payload": {"agents": ["cue", "1"]}},
        {"kind": "physics_rolling_stationary", "t": r(tc), "payload": {"agents": ["cue"]}},
        {"kind": "physics_rolling_stationary", "t": r(t_stop), "payload": {"agents": ["1"]}},
    ]
    return {
        "environment": "pooltool", "task_id": "example_straight_shot",
        "timesteps": steps, "events": events,
        "outcome": {"success": False, "terminal_status": "no_ball_pocketed",
                    "metrics": {"balls_pocketed": 0, "n_events": len(events), "duration_s": r(t_stop)}},
    }


def phyre():
    # PHYRE scene (px, y up): a red user ball dropped onto a static black bar; the green ball rests
    # on the same bar. The red ball falls 60 px and stops on contact (damped for the example).
    g_px = G * 6.0  # PHYRE uses 6 px per metre
    dt = 1.0 / 60.0 * 5  # every 5th physics step
    y0, floor = 150.0, 90.0 + 10.0
    t_hit = math.sqrt(2 * (y0 - floor) / g_px)
    steps = []
    for k in range(12):
        t = k * dt
        if t < t_hit:
            y, vy = y0 - g_px * t * t / 2, -g_px * t
        else:
            y, vy = floor, 0.0
        objs = [
            {"object_index": 0, "shape": "bar", "color": "black", "diameter": 120.0, "x": 128.0, "y": 85.0,
             "angle": 0.0, "vx": 0.0, "vy": 0.0, "angular_velocity": 0.0, "is_user_input": False},
            {"object_index": 1, "shape": "ball", "color": "green", "diameter": 20.0, "x": 170.0, "y": 100.0,
             "angle": 0.0, "vx": 0.0, "vy": 0.0, "angular_velocity": 0.0, "is_user_input": False},
            {"object_index": 2, "shape": "ball", "color": "red", "diameter": 20.0, "x": 100.0, "y": r(y),
             "angle": 0.0, "vx": 0.0, "vy": r(vy), "angular_velocity": 0.0, "is_user_input": True},
        ]
        steps.append({"index": k * 5, "t": r(t), "objects": objs})
    return {
        "environment": "phyre", "task_id": "00000:000",
        "timesteps": steps,
        "events": [
            {"kind": "user_ball_placed", "t": 0.0, "payload": {"agents": ["2"], "x": 100.0, "y": 150.0, "radius": 10.0}},
            {"kind": "contact_begin", "t": r(t_hit), "payload": {"agents": ["2", "0"]}},
        ],
        "outcome": {"success": False, "terminal_status": "NOT_SOLVED", "metrics": {"steps_simulated": 60}},
    }


def iphyre():
    # I-PHYRE scene (px, y down, gravity 100 px/s^2): a red ball rests on a gray eliminable block; the
    # block is clicked away at t = 0.5 s and the ball falls out of the 600 px screen.
    g = 100.0
    dt = 0.25
    t_rm = 0.5
    steps = []
    for k in range(16):
        t = k * dt
        s = max(0.0, t - t_rm)
        y = 290.0 + g * s * s / 2
        objs = []
        if t < t_rm:
            objs.append({"index": 0, "x1": 250.0, "y1": 310.0, "x2": 350.0, "y2": 310.0, "radius": 10.0,
                         "eliminable": 1.0, "dynamic": 0.0, "joint": 0, "spring": 0})
        objs.append({"index": 1, "x1": 100.0, "y1": 500.0, "x2": 200.0, "y2": 520.0, "radius": 10.0,
                     "eliminable": 0.0, "dynamic": 0.0, "joint": 0, "spring": 0})
        objs.append({"index": 2, "x1": 300.0, "y1": r(y), "x2": 300.0, "y2": r(y), "radius": 10.0,
                     "eliminable": 0.0, "dynamic": 1.0, "joint": 0, "spring": 0})
        steps.append({"index": k * 15, "t": r(t), "objects": objs})
    t_exit = t_rm + math.sqrt(2 * (600.0 - 290.0) / g)
    return {
        "environment": "iphyre", "task_id": "support",
        "timesteps": steps,
        "events": [
            {"kind": "scheduled_action", "t": 0.5, "payload": {"x": 300.0, "y": 310.0}},
            {"kind": "action_applied", "t": 0.5, "payload": {"agents": ["0"], "eliminated_object": 0}},
            {"kind": "ball_exit", "t": r(t_exit), "payload": {"agents": ["2"]}},
        ],
        "outcome": {"success": True, "terminal_status": "success",
                    "metrics": {"reward": r(1000 - 10 - t_exit * 60 / 60), "eliminations": 1}},
    }


for name, trace in (("pooltool_straight_shot", pooltool()), ("phyre_drop", phyre()), ("iphyre_support", iphyre())):
    with open(os.path.join(HERE, name + ".json"), "w") as f:
        json.dump(trace, f, indent=1)
        f.write("\n")
