#!/usr/bin/env python
"""Independent re-implementation (numpy only) of the formulas in docs/envs/pool.md ("Physics reference"),
checked against the pooltool traces written by gen_traces.py.

Usage: python verify_formulas.py [GLOB]   (default: traces/shot_*.json next to this script)
pooltool itself is only imported for the non-gross-slip branches of the Stronge cushion model.

Checks:
  1. Motion equations (slide / roll / spin, incl. transitions): evolve each ball's
     post-event state to the time of its next event and compare with the pre-event
     state that pooltool recorded ("before").
  2. Cue strike (InstantaneousPoint + squirt): compare with the stick_ball "after" state.
  3. Ball-ball (FrictionalInelastic + Alciatore friction): compare with ball_ball
     "after" velocities / spins (positions come from make_kiss and are taken as given).
  4. Ball-cushion (Stronge compliant wrapper): compare with cushion "after" states;
     the 1D Stronge solve is re-implemented for the closed-form gross-slip branch and
     pooltool's own 1D routine is used as a black box for stick branches.
  5. Event times: the quartic/quadratic collision conditions are satisfied at the
     recorded event time (|d| - contact distance ~ 0).
"""

from __future__ import annotations

import glob
import json
import math
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

# ---------------- parameters (defaults of pooltool 0.6.0) ----------------
m, R = 0.170097, 0.028575
u_s, u_r, g = 0.2, 0.01, 9.81
u_sp = (10 * 2 / 5 / 9) * R
e_b, e_c, f_c = 0.95, 0.85, 0.2
M_cue, end_mass = 0.567, 0.170097 / 30
EPS = np.finfo(float).eps * 100
STATIONARY, SPINNING, SLIDING, ROLLING, POCKETED = range(5)


def rel_vel(v, w):
    # velocity of the contact point with the cloth: v + w x (-R z)
    return np.array([v[0] - R * w[1], v[1] + R * w[0], 0.0])


def unit(x):
    n = np.linalg.norm(x)
    return x / n


def spin_decay(wz, t):
    if t == 0 or abs(wz) < EPS:
        return wz
    alpha = 5 * u_sp * g / (2 * R)
    t = min(t, abs(wz) / alpha)
    return wz - math.copysign(1.0, wz) * alpha * t


def evolve(s, r, v, w, t):
    r, v, w = r.copy(), v.copy(), w.copy()
    if s in (STATIONARY, POCKETED):
        return s, r, v, w
    if s == SLIDING:
        u = rel_vel(v, w)
        tau = 2 * np.linalg.norm(u) / (7 * u_s * g)
        dt = min(t, tau)
        uh = unit(u)
        r = r + v * dt - 0.5 * u_s * g * dt**2 * uh
        v = v - u_s * g * dt * uh
        zxu = np.cross(uh, [0, 0, 1.0])  # u_hat x z
        w_new = w - 5 / (2 * R) * u_s * g * dt * zxu
        w_new[2] = spin_decay(w[2], dt)
        w = w_new
        if t < tau:
            return SLIDING, r, v, w
        s, t = ROLLING, t - tau
    if s == ROLLING:
        tau = np.linalg.norm(v) / (u_r * g)
        dt = min(t, tau)
        vh = unit(v)
        r = r + v * dt - 0.5 * u_r * g * dt**2 * vh
        v = v - u_r * g * dt * vh
        wz = spin_decay(w[2], dt)
        w = np.array([-v[1] / R, v[0] / R, wz])
        if t < tau:
            return ROLLING, r, v, w
        s, t = SPINNING, t - tau
    if s == SPINNING:
        tau = abs(w[2]) * 2 / 5 * R / u_sp / g
        w = w.copy()
        w[2] = spin_decay(w[2], t)
        return (SPINNING if t < tau else STATIONARY), r, v, w
    raise ValueError(s)


def rot(v, phi):
    c, s_ = math.cos(phi), math.sin(phi)
    return np.array([c * v[0] - s_ * v[1], s_ * v[0] + c * v[1], v[2]])


def cue_strike(V0, phi_deg, theta_deg, a, b):
    th = math.radians(theta_deg)
    cue_c = math.sqrt(1 - a * a - b * b)
    ba, bc, bb = a, math.cos(th) * cue_c - math.sin(th) * b, math.sin(th) * cue_c + math.cos(th) * b
    A, C, B = R * ba, R * bc, R * bb  # metres
    I_m = 2 / 5 * R**2
    temp = A**2 + (B * math.cos(th)) ** 2 + (C * math.sin(th)) ** 2 - 2 * B * C * math.cos(th) * math.sin(th)
    vmag = 2 * V0 / (1 + m / M_cue + temp / I_m)
    v_B = np.array([0.0, -vmag * math.cos(th), 0.0])
    w_B = vmag / I_m * np.array([-C * math.sin(th) + B * math.cos(th), A * math.sin(th), -A * math.cos(th)])
    ang = math.radians(phi_deg) + math.pi / 2
    v, w = rot(v_B, ang), rot(w_B, ang)
    mr = m / end_mass
    An = 1 - ba**2
    alpha = -math.atan2(2.5 * ba * math.sqrt(An), 1 + mr + 2.5 * An)
    return rot(v, alpha), w


def ball_ball(r1, v1, w1, r2, v2, w2):
    d = r2 - r1
    # Alciatore friction from tangential surface velocities (pre-rotation, 3D)
    n = unit(d)

    def tsv(v, w, dd):
        return v - np.dot(v, dd) * dd + np.cross(w, R * dd)

    vrel = np.linalg.norm(tsv(v1, w1, n) - tsv(v2, w2, -n))
    ub = 0.009951 + 0.108 * math.exp(-1.088 * vrel)
    th = math.atan2(d[1], d[0])
    v1, w1, v2, w2 = (rot(x, -th) for x in (v1, w1, v2, w2))
    v1n = 0.5 * ((1 - e_b) * v1[0] + (1 + e_b) * v2[0])
    v2n = 0.5 * ((1 + e_b) * v1[0] + (1 - e_b) * v2[0])
    dvn = abs(v2n - v1n)
    w1n, w2n = w1[0], w2[0]
    for x in (v1, v2, w1, w2):
        x[0] = 0.0
    X = np.array([1.0, 0, 0])
    v12c = (v1 + np.cross(w1, R * X)) - (v2 + np.cross(w2, -R * X))
    has = np.linalg.norm(v12c) > EPS
    use_noslip = not has
    if has:
        dv = ub * dvn * -unit(v12c)
        dw = 2.5 / R * np.cross(X, dv)
        v1f, w1f, v2f, w2f = v1 + dv, w1 + dw, v2 - dv, w2 + dw
        v12s = (v1f + np.cross(w1f, R * X)) - (v2f + np.cross(w2f, -R * X))
        use_noslip = np.dot(v12c, v12s) <= 0
    if use_noslip:
        dv = -(1 / 7) * (v1 - v2 + R * np.cross(w1 + w2, X))
        dw = -(5 / 14) * (np.cross(X, v1 - v2) / R + w1 + w2)
        v1f, w1f, v2f, w2f = v1 + dv, w1 + dw, v2 - dv, w2 + dw
    v1f[0], v2f[0], w1f[0], w2f[0] = v1n, v2n, w1n, w2n
    v1f, w1f, v2f, w2f = (rot(x, th) for x in (v1f, w1f, v2f, w2f))
    v1f[2] = v2f[2] = 0.0
    return continually_touching(r1, v1f, r2, v2f) + (w1f, w2f)


def continually_touching(r1, v1, r2, v2):
    """CoreBallBallCollision.resolve_continually_touching (post-solve fix-up)."""
    s1, s2 = np.linalg.norm(v1), np.linalg.norm(v2)
    if not (s1 > 0 and s2 > 0):
        return v1, v2
    loc = unit(r2 - r1)
    l1, l2 = np.dot(v1, loc), np.dot(v2, loc)
    if abs(l2 - l1) < 0.01 and np.dot(v1, v2) / (s1 * s2) > 0.9:
        if l1 > l2:
            st = 0.10 * l1
            n1, n2 = l1 - st, l2 + st
        else:
            st = 0.10 * l2
            n1, n2 = l1 + st, l2 - st
        v1 = v1 - l1 * loc + n1 * loc
        v2 = v2 - l2 * loc + n2 * loc
    return v1, v2


def cushion_normal_3d(table, kind, cid, pos):
    if kind == "linear":
        c = table["linear_cushions"][cid]
        p1, p2 = np.array(c["p1"]), np.array(c["p2"])
        ax = unit(p2 - p1)
        rr = pos - p1
        return unit(rr - np.dot(rr, ax) * ax)
    c = table["circular_cushions"][cid]
    return unit(pos - np.array(c["center"]))


def stronge_1d(v_t0, v_n0, mu, e, omega_ratio=1.8):
    bt, bn = 3.5, 1.0
    eta2 = (bt / bn) / omega_ratio**2
    r = v_t0 / v_n0
    if r > mu * ((1 + e) * bt / bn - eta2 / e):  # gross slip, closed form
        return v_t0 - mu * v_n0 * (bt / bn) * (1 + e), -e * v_n0, "gross_slip"
    from pooltool.physics.resolve.stronge_compliant import (
        resolve_collinear_compliant_frictional_inelastic_collision as f,
    )

    vtf, vnf = f(v_t0, v_n0, m, bt, bn, mu, e, 1e3, eta2)
    return vtf, vnf, ("stick_slip" if r < mu * eta2 else "slip_stick_slip")


def cushion(table, kind, cid, r, v, w):
    n = cushion_normal_3d(table, kind, cid, r)
    vc = v + np.cross(w, -R * n)
    v_n0 = float(np.dot(n, vc))
    nxv = np.cross(n, vc)
    v_t0 = -np.linalg.norm(nxv)
    t = np.cross(nxv, n) / v_t0 if v_t0 != 0 else np.zeros(3)
    vtf, vnf, regime = stronge_1d(v_t0, v_n0, f_c, e_c)
    v = v + (vnf - v_n0) / 1.0 * n
    dvt = (vtf - v_t0) / 3.5
    v = v + dvt * t
    w = w + (2.5 / R) * np.cross(-n, dvt * t)
    v[2] = 0.0
    return v, w, regime


def arr(d, k):
    return np.array(d[k], dtype=float)


def main(pattern):
    err = defaultdict(float)
    counts = defaultdict(int)
    regimes = defaultdict(int)
    for path in sorted(glob.glob(pattern)):
        tr = json.load(open(path))
        table = tr["table"]
        last = {}  # ball id -> (t, s, r, v, w) after its last event
        for bid, st in tr["initial"].items():
            last[bid] = (0.0, st["s"], arr(st, "pos"), arr(st, "vel"), arr(st, "avel"))
        for ev in tr["events"]:
            et = ev["time"]
            balls = [a for a in ev["agents"] if a["agent_type"] == "ball" and "before" in a]
            # 1. motion equations
            for a in balls:
                t0, s0, r0, v0, w0 = last[a["id"]]
                s1, r1, v1, w1 = evolve(s0, r0, v0, w0, et - t0)
                b = a["before"]
                e = max(np.abs(r1 - arr(b, "pos")).max(), np.abs(v1 - arr(b, "vel")).max(), R * np.abs(w1 - arr(b, "avel")).max())
                err["motion"] = max(err["motion"], e)
                counts["motion"] += 1
                if s1 != b["s"] and ev["type"] not in ("sliding_rolling", "rolling_spinning", "rolling_stationary", "spinning_stationary"):
                    counts["motion_state_mismatch"] += 1
            typ = ev["type"]
            if typ == "stick_ball":
                c = tr["meta"]["cue"]
                v, w = cue_strike(c["V0"], c["phi"], c["theta"], c["a"], c["b"])
                aft = balls[0]["after"]
                err["cue_strike"] = max(err["cue_strike"], np.abs(v - arr(aft, "vel")).max(), R * np.abs(w - arr(aft, "avel")).max())
                counts["cue_strike"] += 1
            elif typ == "ball_ball":
                A, B = balls
                v1f, v2f, w1f, w2f = ball_ball(
                    arr(A["after"], "pos"), arr(A["before"], "vel"), arr(A["before"], "avel"),
                    arr(B["after"], "pos"), arr(B["before"], "vel"), arr(B["before"], "avel"),
                )
                e = max(
                    np.abs(v1f - arr(A["after"], "vel")).max(), np.abs(v2f - arr(B["after"], "vel")).max(),
                    R * np.abs(w1f - arr(A["after"], "avel")).max(), R * np.abs(w2f - arr(B["after"], "avel")).max(),
                )
                # resolve_continually_touching may alter velocities in rare cases
                err["ball_ball"] = max(err["ball_ball"], e)
                counts["ball_ball"] += 1
                # 5. event-time condition: centre distance == 2R (before make_kiss)
                dd = np.linalg.norm(arr(A["before"], "pos")[:2] - arr(B["before"], "pos")[:2])
                err["bb_contact_distance"] = max(err["bb_contact_distance"], abs(dd - 2 * R))
            elif typ in ("ball_linear_cushion", "ball_circular_cushion"):
                kind = "linear" if typ == "ball_linear_cushion" else "circular"
                a = balls[0]
                v, w, regime = cushion(table, kind, ev["ids"][1], arr(a["after"], "pos"), arr(a["before"], "vel"), arr(a["before"], "avel"))
                regimes[regime] += 1
                err["cushion"] = max(err["cushion"], np.abs(v - arr(a["after"], "vel")).max(), R * np.abs(w - arr(a["after"], "avel")).max())
                counts["cushion"] += 1
            elif typ == "ball_pocket":
                a = balls[0]
                pk = table["pockets"][ev["ids"][1]]
                dd = np.linalg.norm(arr(a["before"], "pos")[:2] - np.array(pk["center"][:2]))
                err["pocket_entry_distance"] = max(err["pocket_entry_distance"], abs(dd - pk["radius"]))
                counts["ball_pocket"] += 1
            for a in balls:
                aft = a.get("after")
                if aft is not None:
                    last[a["id"]] = (et, aft["s"], arr(aft, "pos"), arr(aft, "vel"), arr(aft, "avel"))
        # continuized timesteps vs evolve from the preceding event
    print(json.dumps({"max_abs_error": err, "counts": counts, "stronge_regimes": regimes}, indent=1))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else str(Path(__file__).resolve().parent / "traces" / "shot_*.json"))
