"""Prelude: Contacts for the event-grounded detectors: the event log when the trace has one, else contacts inferred from recorded velocities (`_kinematic`). Its `_events` replaces the one of `_common.py`.

library.toml prepends it to the detectors that list it; it defines no find_pattern."""


KICK_ACCEL = 3.0  # m/s²: more than cloth friction (sliding ≈ 2 m/s²) can change a velocity
KICK_FLOOR = 0.05  # m/s
CONTACT_SLACK = 1.15  # × the sum of radii


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
                        near[a].append((b, t0 + s_))
                        near[b].append((a, t0 + s_))
            # A kick travels along touching balls (a struck ball pressed against another passes the
            # impulse on and barely moves): the shortest chain between two kicked balls collided.
            hits = {}
            kset = set(kicked)
            for src in kicked:
                back = {src: None}
                queue = [src]
                while queue:
                    x = queue.pop(0)
                    for y, ty in near.get(x, ()):
                        if y not in back:
                            back[y] = (x, ty)
                            queue.append(y)
                for dst in kicked:
                    if dst == src or dst not in back:
                        continue
                    y = dst
                    while back[y] is not None:
                        x, ty = back[y]
                        hits[tuple(sorted((x, y)))] = ty
                        y = x
            # A kicked ball touching no other kicked ball but touching one at rest hit that one.
            for b in kicked:
                if not any(b in pair for pair in hits) and near.get(b):
                    y, ty = min(near[b], key=lambda e: e[1])
                    hits[tuple(sorted((b, y)))] = ty
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
