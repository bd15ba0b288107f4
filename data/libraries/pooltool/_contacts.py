"""Prelude: Contacts for the event-grounded detectors: the event log when the trace has one, else contacts inferred from recorded velocities (`_kinematic`). Its `_events` replaces the one of `_common.py`.

library.toml prepends it to the detectors that list it; it defines no find_pattern."""


KICK_ACCEL = 3.0  # m/s²: more than cloth friction (sliding ≈ 2 m/s²) can change a velocity
KICK_FLOOR = 0.05  # m/s
CONTACT_SLACK = 1.15  # × the sum of radii
IMPULSE_MIN = 0.02  # m/s: the smallest ball-ball impulse (as a velocity change) taken as a collision
FRICTION_ACCEL = 1.0  # m/s²: cloth friction (sliding) that an impulse fit may mistake for a push


def _closest(pa, va, pb, vb, dt):
    """Time in [0, dt] of closest approach of two balls moving straight, and the distance then."""
    rx, ry = pb[0] - pa[0], pb[1] - pa[1]
    ux, uy = vb[0] - va[0], vb[1] - va[1]
    uu = ux * ux + uy * uy
    s = 0.0 if uu < 1e-12 else max(0.0, min(dt, -(rx * ux + ry * uy) / uu))
    dx, dy = rx + ux * s, ry + uy * s
    return s, (dx * dx + dy * dy) ** 0.5


def _kinematic(trace):
    """Contact events inferred from the timesteps alone, for traces without an event log: a ball whose
    recorded velocity changes between two frames by more than friction allows was kicked; two kicked balls
    that come within touching distance in that interval collided, a kicked ball alone hit a cushion; a
    ball's first `pocketed` state is its drop; the cue ball's first motion is the strike."""
    steps = trace.get("timesteps") or ()
    out = []
    prev = {}
    for k, s in enumerate(steps):
        t = float(s.get("t", 0.0))
        cur = {}
        for o in s.get("objects", ()):
            cur[str(o.get("ball_id"))] = o
        if k == 0:
            cue = cur.get("cue")
            if cue is not None and _speed(cue) > 1e-6:
                out.append(("physics_stick_ball", t, {"ball": "cue", "agents": ["cue_stick", "cue"]}))
        else:
            t0 = float(steps[k - 1].get("t", 0.0))
            dt = max(t - t0, 1e-9)
            kicked = []
            for b, o in cur.items():
                p = prev.get(b)
                if p is None:
                    continue
                if o.get("motion_state") == "pocketed":
                    if p.get("motion_state") != "pocketed":
                        out.append(("physics_ball_pocket", t, {"ball": b, "pocket": "?"}))
                    continue
                v0, v1 = p.get("velocity") or (0, 0), o.get("velocity") or (0, 0)
                if b == "cue" and _speed(p) < 1e-6 and k == 1 and not out:
                    if _speed(o) > 1e-6:
                        out.append(("physics_stick_ball", t0, {"ball": "cue", "agents": ["cue_stick", "cue"]}))
                    continue
                dv = ((v1[0] - v0[0]) ** 2 + (v1[1] - v0[1]) ** 2) ** 0.5
                if dv > KICK_ACCEL * dt + KICK_FLOOR:
                    kicked.append(b)
            # Contact graph of the interval: pairs that come within touching distance, moving straight
            # forwards from the earlier frame or backwards from the later one.
            live = [b for b in cur if b in prev and cur[b].get("motion_state") != "pocketed"]
            near = {b: [] for b in live}
            for i, a in enumerate(live):
                for b in live[i + 1:]:
                    pa, pb, qa, qb = prev[a], prev[b], cur[a], cur[b]
                    s_, d = _closest(pa["position"], pa["velocity"], pb["position"], pb["velocity"], dt)
                    va = [-x for x in qa["velocity"][:2]]
                    vb = [-x for x in qb["velocity"][:2]]
                    s2, d2 = _closest(qa["position"], va, qb["position"], vb, dt)
                    if d2 < d:
                        s_, d = dt - s2, d2
                    reach = CONTACT_SLACK * (float(pa.get("radius") or 0.028575) + float(pb.get("radius") or 0.028575))
                    if d <= reach:
                        # Line of centres (a -> b) at the closest approach.
                        ss = s_
                        px = [float(pa["position"][i]) + float(pa["velocity"][i]) * ss for i in (0, 1)]
                        qx = [float(pb["position"][i]) + float(pb["velocity"][i]) * ss for i in (0, 1)]
                        nx, ny = qx[0] - px[0], qx[1] - px[1]
                        nn = (nx * nx + ny * ny) ** 0.5 or 1.0
                        n = (nx / nn, ny / nn)
                        if a < b:
                            near[a].append((b, t0 + s_, n))
                        else:
                            near[b].append((a, t0 + s_, (-n[0], -n[1])))
            # Impulses on the contact graph: each pair that touches in the interval may push its two balls
            # apart along the line of centres (equal masses, so as velocity changes J >= 0). The
            # non-negative J that best explain every ball's velocity change (a least-squares fit, by
            # projected coordinate descent) tell which pairs collided: a ball pressed between two others
            # passes the impulse on, and a pair that merely sits close takes none.
            hits = {}
            pairs = []
            for a in near:
                for b, ty, n in near[a]:
                    if a < b:
                        pairs.append((a, b, ty, n))
            if pairs:
                dv = {}
                for b in live:
                    v0, v1 = prev[b]["velocity"], cur[b]["velocity"]
                    dv[b] = [float(v1[0]) - float(v0[0]), float(v1[1]) - float(v0[1])]
                res = {b: list(v) for b, v in dv.items()}
                J = [0.0] * len(pairs)
                for _ in range(60):
                    moved = 0.0
                    for i, (a, b, ty, n) in enumerate(pairs):
                        ra, rb = res[a], res[b]
                        step = ((rb[0] - ra[0]) * n[0] + (rb[1] - ra[1]) * n[1]) / 2.0
                        new = max(0.0, J[i] + step)
                        d = new - J[i]
                        if d != 0.0:
                            J[i] = new
                            ra[0] += d * n[0]
                            ra[1] += d * n[1]
                            rb[0] -= d * n[0]
                            rb[1] -= d * n[1]
                            moved = max(moved, abs(d))
                    if moved < 1e-6:
                        break
                for i, (a, b, ty, n) in enumerate(pairs):
                    if J[i] >= IMPULSE_MIN + FRICTION_ACCEL * dt:
                        hits[(a, b)] = ty
                kicked = [b for b in kicked if (res[b][0] ** 2 + res[b][1] ** 2) ** 0.5 > KICK_ACCEL * dt + KICK_FLOOR]
            paired = set()
            for (a, b), ty in sorted(hits.items(), key=lambda h: h[1]):
                out.append(("physics_ball_ball", ty, {"agents": [a, b]}))
                paired.add(a)
                paired.add(b)
            for b in kicked:
                if b not in paired:
                    out.append(("physics_ball_linear_cushion", t0 + dt / 2, {"ball": b, "cushion": "?"}))
        prev = cur
    return out


# The event-log reader of _common.py, kept under another name before _events is replaced below.
_events_logged = _events


def _events(trace, kinds):
    """(t, payload) of events of the given kinds: from the event log, or inferred from the timesteps when
    the trace has no physics events."""
    if any(str(e.get("kind", "")).startswith("physics_") for e in trace.get("events", ())):
        return _events_logged(trace, kinds)
    out = [(t, p) for k, t, p in _kinematic(trace) if k in kinds or (k == "physics_ball_linear_cushion" and "physics_ball_circular_cushion" in kinds)]
    out.sort(key=lambda x: x[0])
    return out
