"""support relationship: a body rests on another (above it, y up) for at least MIN_S: a contact
episode in which the upper body's speed stays at most REST_V px/s over at least MIN_S. Span: the resting
part of the contact."""

MIN_S = 0.5
REST_V = 5.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for g in _contacts(trace):
        x, y = g["pair"]
        a0, b0 = _at(ts, g["t0"]), _at(ts, g["t1"])
        ox, oy = _body_at(trace, a0, x), _body_at(trace, a0, y)
        if ox is None or oy is None:
            continue
        top, low = (x, y) if float(ox["y"]) > float(oy["y"]) else (y, x)
        if top not in kin or _is_static(kin, top):
            continue
        ks = list(range(a0, b0 + 1))
        for i, j in _runs(ks, ts, [_speed_at(kin, top, k) <= REST_V for k in ks], MIN_S):
            a, b = ks[i], ks[j]
            out.append({"label": "support relationship", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {top: _detail(trace, a, b, top, "supported object"),
                                                          low: _detail(trace, a, b, low, "supporter")},
                                       "duration_s": round(ts[b] - ts[a], 3)}})
    return out
