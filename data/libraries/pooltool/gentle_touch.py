"""gentle touch: two balls meet softly (approach speed under 0.3 m/s), nudging rather than driving the
struck ball.

Uses the merged `physics_ball_ball` collisions; the approach speed (along the line of centres, at the
burst's first contact) comes from the event when it carries one (annotrace's `approach_speed`), else from
the recorded states of the last timestep before the contact, moved on to its time. Without an event log
the collisions are inferred from the recorded velocities (`_kinematic`)."""


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
        first = g["payloads"][0]
        ox, oy = _state(trace, a, x), _state(trace, a, y)
        if isinstance(first.get("approach_speed"), (int, float)):
            v = abs(float(first["approach_speed"]))
        elif ox is not None and oy is not None:
            # Along the line of centres at the first contact, both balls moved on from the frame before.
            dt = g["t0"] - ts[a]
            px = [ox["position"][i] + ox["velocity"][i] * dt for i in (0, 1)]
            py = [oy["position"][i] + oy["velocity"][i] * dt for i in (0, 1)]
            n = [py[0] - px[0], py[1] - px[1]]
            nn = (n[0] ** 2 + n[1] ** 2) ** 0.5
            if nn < 1e-9:
                continue
            v = abs(((ox["velocity"][0] - oy["velocity"][0]) * n[0] + (ox["velocity"][1] - oy["velocity"][1]) * n[1]) / nn)
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
