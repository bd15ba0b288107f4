"""ball slowing: a rolling ball loses most of its speed and comes to rest.

For each rolling episode that ends with the ball stopping (`physics_rolling_stationary`), the span runs
from the first timestep at which its speed (the recorded velocity, not displacement between frames, which
misleads on uneven frame spacing) has fallen to half the episode's starting speed, to the stop. Balls that
start rolling slower than 0.05 m/s are ignored (nothing visibly slows). Without an event log, a run of
`rolling` frames followed by a `stationary` one."""


MERGE_S = 0.05


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    stops = {}
    for t, p in _events(trace, ("physics_rolling_stationary",)):
        if p.get("ball") is not None:
            stops.setdefault(str(p["ball"]), []).append(t)
    out = []
    logged = any(str(e.get("kind", "")).startswith("physics_") for e in trace.get("events", ()))
    for bid, t0, t1 in _episodes(trace, ("physics_sliding_rolling",), None, "rolling"):
        s, e, a, b = _span(idx, ts, t0, t1)
        if logged:
            if not any(abs(t - t1) < 1e-9 for t in stops.get(bid, [])):
                continue
        elif (_state(trace, b, bid) or {}).get("motion_state") != "stationary":
            continue  # without a log: the roll must end with the ball at rest in the next frame
        v0 = _speed(_state(trace, min(a + 1, b), bid))
        if v0 < 0.05:
            continue
        k = a + 1
        while k < b and _speed(_state(trace, k, bid)) > 0.5 * v0:
            k += 1
        k = min(k, b)
        out.append({"label": "ball slowing", "start_timestep": idx[k], "end_timestep": e,
                    "parameters": {"object_details": {bid: _detail(trace, k, b, bid, "slowing ball")},
                                   "start_speed": round(v0, 4), "t_stop": round(t1, 4)}})
    return out
