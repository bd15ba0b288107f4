"""ball collision: two balls hit each other.

Grounded in `physics_ball_ball` events. Contacts of the same pair closer than 50 ms are one collision
(pooltool resolves a frozen or pressed pair as a burst of contacts), so the pattern spans the burst.
Roles: the ball moving faster just before is the striking ball.
Without an event log (imported traces) the contacts are inferred from the recorded velocities
(`_kinematic`).
"""


MERGE_S = 0.05


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    evs = _events(trace, ("physics_ball_ball",))
    out = []
    for g in _merge(evs, lambda p: tuple(sorted(str(x) for x in (p.get("agents") or [])[:2])) or None):
        if len(g["key"]) != 2:
            continue
        s, e, a, b = _span(idx, ts, g["t0"], g["t1"])
        x, y = g["key"]
        if _speed(_state(trace, a, y)) > _speed(_state(trace, a, x)):
            x, y = y, x
        speeds = [float(p["approach_speed"]) for p in g["payloads"] if isinstance(p.get("approach_speed"), (int, float))]
        params = {"object_details": {x: _detail(trace, a, b, x, "striking ball"),
                                     y: _detail(trace, a, b, y, "struck ball")},
                  "t": round(g["t0"], 4), "contacts": g["n"]}
        if speeds:
            params["approach_speed"] = round(max(abs(v) for v in speeds), 4)
        out.append({"label": "ball collision", "start_timestep": s, "end_timestep": e, "parameters": params})
    return out
