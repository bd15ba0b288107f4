"""gentle touch: two balls meet softly (approach speed under 0.3 m/s), nudging rather than driving the
struck ball.

Uses the merged `physics_ball_ball` collisions; the approach speed comes from the event, or from the
recorded velocities at the last timestep before contact when the event does not carry it."""


MERGE_S = 0.05


SOFT = 0.3


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
        speeds = [abs(float(p["approach_speed"])) for p in g["payloads"] if isinstance(p.get("approach_speed"), (int, float))]
        ox, oy = _state(trace, a, x), _state(trace, a, y)
        if speeds:
            v = max(speeds)
        elif ox is not None and oy is not None:
            v = ((ox["velocity"][0] - oy["velocity"][0]) ** 2 + (ox["velocity"][1] - oy["velocity"][1]) ** 2) ** 0.5
        else:
            continue
        if v >= SOFT:
            continue
        if _speed(oy) > _speed(ox):
            x, y = y, x
        out.append({"label": "gentle touch", "start_timestep": s, "end_timestep": e,
                    "parameters": {"object_details": {x: _detail(trace, a, b, x, "touching ball"),
                                                      y: _detail(trace, a, b, y, "touched ball")},
                                   "approach_speed": round(v, 4), "t": round(g["t0"], 4)}})
    return out
