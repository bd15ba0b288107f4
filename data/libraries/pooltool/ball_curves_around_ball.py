"""ball curves around ball: a moving ball's path bends (swerve from side spin while it slides) as it
passes close to another ball without touching it.

Between two consecutive events of a ball (so no collision or cushion inside) at least MIN_S apart (a
path, not the milliseconds between two contacts of a ball in a cluster), its heading must turn by more
than 8 degrees from the first event to the second, and another ball must come within 4 ball radii of
its path at the same timesteps while the two never collide. The velocities at the two event times are
carried on from the nearest two frames inside the slide along their change (a sliding ball's velocity
changes at a constant rate), so the turn is measured over the whole slide, not just between frames."""


TURN_COS = 0.990  # cos 8°
NEAR_RADII = 4.0
MIN_S = 0.05


def _carried(p, q, tp, tq, t):
    """Velocity at time t, carried on linearly from frames p (time tp) and q (time tq)."""
    vp, vq = p.get("velocity") or (0.0, 0.0), q.get("velocity") or (0.0, 0.0)
    f = (t - tp) / (tq - tp) if tq != tp else 0.0
    return {"velocity": (float(vp[0]) + f * (float(vq[0]) - float(vp[0])),
                         float(vp[1]) + f * (float(vq[1]) - float(vp[1])))}


def _ball_events(trace):
    """Times of each ball's physics events, sorted, by ball id (one pass over the event log)."""
    out = {}
    for e in trace.get("events", []):
        p = e.get("payload") or {}
        k = e.get("kind", "")
        if not k.startswith("physics_") or e.get("t") is None:
            continue
        t = float(e["t"])
        for bid in set(_roles(k, p)[0]):
            out.setdefault(bid, []).append(t)
    for times in out.values():
        times.sort()
    return out


def _by_id(step):
    """The step's objects by ball id (the first object of each id, as `_state` finds it)."""
    m = {}
    for o in step.get("objects", []):
        m.setdefault(str(o.get("ball_id")), o)
    return m


def _unit(o):
    v = o.get("velocity") or (0.0, 0.0)
    n = (float(v[0]) ** 2 + float(v[1]) ** 2) ** 0.5
    return (float(v[0]) / n, float(v[1]) / n) if n > 1e-3 else None


def find_pattern(trace):
    steps = trace.get("timesteps") or ()
    if len(steps) < 3:
        return []
    idx, ts = _clock(trace)
    ids = [str(o.get("ball_id")) for o in steps[0].get("objects", [])]
    touched = set()
    for t, p in _events(trace, ("physics_ball_ball",)):
        ag = [str(x) for x in (p.get("agents") or [])[:2]]
        if len(ag) == 2:
            touched.add((ag[0], ag[1]))
            touched.add((ag[1], ag[0]))
    out = []
    events = _ball_events(trace) if ids else {}
    for bid in ids:
        times = events.get(bid, []) + [ts[-1]]
        for t0, t1 in zip(times, times[1:]):
            a, b = _at(ts, t0) + 1, _at(ts, t1)
            if b - a < 2 or t1 - t0 < MIN_S - 1e-9:
                continue
            oa, ob = _state(trace, a, bid), _state(trace, b, bid)
            if oa is None or ob is None or oa.get("motion_state") != "sliding":
                continue
            oa1, ob1 = _state(trace, a + 1, bid), _state(trace, b - 1, bid)
            if oa1 is not None and ob1 is not None and ob.get("motion_state") == "sliding":
                va = _carried(oa, oa1, ts[a], ts[a + 1], t0)
                vb = _carried(ob1, ob, ts[b - 1], ts[b], t1)
            else:
                va, vb = oa, ob
            ua, ub = _unit(va), _unit(vb)
            if ua is None or ub is None or ua[0] * ub[0] + ua[1] * ub[1] > TURN_COS:
                continue
            r = float(oa.get("radius") or 0.028575)
            best = None
            maps = None
            for other in ids:
                if other == bid or (bid, other) in touched:
                    continue
                if maps is None:
                    maps = [_by_id(steps[k]) for k in range(a, b + 1)]
                for k in range(a, b + 1):
                    m = maps[k - a]
                    p, q = m.get(bid), m.get(other)
                    if p is None or q is None or q.get("motion_state") == "pocketed":
                        continue
                    d = ((p["position"][0] - q["position"][0]) ** 2 + (p["position"][1] - q["position"][1]) ** 2) ** 0.5
                    if d < NEAR_RADII * r and (best is None or d < best[0]):
                        best = (d, other, k)
            if best is None:
                continue
            d, other, k = best
            out.append({"label": "ball curves around ball", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {
                            bid: _detail(trace, a, b, bid, "curving ball"),
                            other: _detail(trace, a, b, other, "obstacle ball")},
                            "closest_distance": round(d, 4), "closest_timestep": idx[k]}})
    return out
