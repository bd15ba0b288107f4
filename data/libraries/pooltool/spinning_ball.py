"""spinning ball: a ball spins in place about the vertical axis (pooltool's `spinning` state), from its
rolling-to-spinning transition until it stops or is hit."""


MERGE_S = 0.05


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    out = []
    for bid, t0, t1 in _episodes(trace, ("physics_rolling_spinning",), None, "spinning"):
        s, e, a, b = _span(idx, ts, t0, t1)
        o = _state(trace, min(a + 1, b), bid) or {}
        w = o.get("angular_velocity") or (0.0, 0.0, 0.0)
        out.append({"label": "spinning ball", "start_timestep": s, "end_timestep": e,
                    "parameters": {"object_details": {bid: _detail(trace, a, b, bid, "spinning ball")},
                                   "t_start": round(t0, 4), "t_end": round(t1, 4),
                                   "spin_rate": round(abs(float(w[2])), 3)}})
    return out
