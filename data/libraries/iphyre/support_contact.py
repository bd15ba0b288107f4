"""support contact: one object rests on (is held up by) another.

A contact episode (event log, or capsule geometry without one; chatter merged within 50 ms) that lasts
at least MIN_S, in which the contact normal from the lower object to the upper one points upwards within
MAX_TILT_DEG of vertical (so side contacts are not support). The supported object is the dynamic one
above; the supporter may be static, eliminable or dynamic. The span is the contact episode: from the
first frame of contact to its end (a removal or the object rolling off ends it).
"""

MIN_S = 0.3
MAX_TILT_DEG = 60.0
COS_TILT = 0.5  # cos(60 degrees)


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    out = []
    for g in _contacts(trace):
        if g["t1"] - g["t0"] < MIN_S:
            continue
        x, y = g["pair"]
        s, e, a, b = _span(idx, ts, g["t0"], g["t1"])
        # Geometry a little after the contact began (the impact frame can still be penetrating).
        k = _at(ts, min(g["t0"] + 0.1, g["t1"]))
        ox, oy = _obj_at(trace, k, x), _obj_at(trace, k, y)
        if ox is None or oy is None:
            continue
        nx, ny = _normal(ox, oy)  # from x towards y
        if -ny >= COS_TILT:
            top, low = y, x  # y is above x (screen y grows downwards)
        elif ny >= COS_TILT:
            top, low = x, y
        else:
            continue
        ot = ox if top == x else oy
        if not ot.get("dynamic"):
            continue
        params = {"object_details": {top: _detail(trace, a, b, top, "supported object"),
                                     low: _detail(trace, a, b, low, "supporter")},
                  "duration_s": round(g["t1"] - g["t0"], 3), "until_end": not g["ended"]}
        out.append({"label": "support contact", "start_timestep": s, "end_timestep": e, "parameters": params})
    return out
