"""ball curves around ball: a moving ball's path bends (swerve from side spin while it slides) as it
passes close to another ball without touching it.

Between two consecutive events of a ball (so no collision or cushion inside), its heading — from the
recorded velocity — must turn by more than 8 degrees, and another ball must come within 4 ball radii of
its path at the same timesteps while the two never collide."""


TURN_COS = 0.990  # cos 8°
NEAR_RADII = 4.0


def _ball_events(trace, bid):
    out = []
    for e in trace.get("events", []):
        p = e.get("payload") or {}
        k = e.get("kind", "")
        if not k.startswith("physics_") or e.get("t") is None:
            continue
        balls = _roles(k, p)[0]
        if bid in balls:
            out.append(float(e["t"]))
    return sorted(out)


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
    for bid in ids:
        times = _ball_events(trace, bid) + [ts[-1]]
        for t0, t1 in zip(times, times[1:]):
            a, b = _at(ts, t0) + 1, _at(ts, t1)
            if b - a < 2:
                continue
            oa, ob = _state(trace, a, bid), _state(trace, b, bid)
            if oa is None or ob is None or oa.get("motion_state") != "sliding":
                continue
            ua, ub = _unit(oa), _unit(ob)
            if ua is None or ub is None or ua[0] * ub[0] + ua[1] * ub[1] > TURN_COS:
                continue
            r = float(oa.get("radius") or 0.028575)
            best = None
            for other in ids:
                if other == bid or (bid, other) in touched:
                    continue
                for k in range(a, b + 1):
                    p, q = _state(trace, k, bid), _state(trace, k, other)
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
