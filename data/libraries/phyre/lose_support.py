"""lose support: a body that rested on another (at most REST_V px/s for at least MIN_REST_S while in
contact, above it) leaves it and falls (downward speed at least FALL_V px/s within AFTER_S of the contact
ending). Span: from the last resting frame to the first falling frame."""

REST_V = 5.0
MIN_REST_S = 0.3
FALL_V = 20.0
AFTER_S = 1.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for g in _contacts(trace):
        if not g["ended"]:
            continue
        x, y = g["pair"]
        a0, b0 = _at(ts, g["t0"]), _at(ts, g["t1"])
        ox, oy = _body_at(trace, a0, x), _body_at(trace, a0, y)
        if ox is None or oy is None:
            continue
        top, low = (x, y) if float(ox["y"]) > float(oy["y"]) else (y, x)
        if top not in kin or _is_static(kin, top):
            continue
        rest = [k for k in range(a0, b0 + 1) if _speed_at(kin, top, k) <= REST_V]
        if not rest or ts[rest[-1]] - ts[rest[0]] < MIN_REST_S:
            continue
        k = rest[-1]
        fall = None
        while k < len(ts) and ts[k] <= g["t1"] + AFTER_S:
            if _vel(kin, top, k)[1] <= -FALL_V:
                fall = k
                break
            k += 1
        if fall is None:
            continue
        a, b = rest[-1], fall
        out.append({"label": "lose support", "start_timestep": idx[a], "end_timestep": idx[b],
                    "parameters": {"object_details": {top: _detail(trace, a, b, top, "object losing support"),
                                                      low: _detail(trace, a, b, low, "former supporter")},
                                   "t_contact_end": round(g["t1"], 4)}})
    return out
