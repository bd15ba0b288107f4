"""moving object hits stationary object: a moving body strikes one at rest.

Grounded in `contact_begin` events (a pair's contact beginning again within 50 ms of its end is the same
contact). In the last frame before the contact one body moves at at least MOVING_V px/s and the other is
at rest (at most AT_REST_V px/s, e.g. a wall, a static bar or a resting body). The pattern spans that
frame to the first frame at or after the contact (frames are 0.1 s apart, contacts are at physics-step
resolution).
"""

MOVING_V = 20.0
AT_REST_V = 5.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for g in _contacts(trace):
        x, y = g["pair"]
        pre = _at(ts, g["t0"] - 1e-9) if "t_seen" not in g else _at(ts, g["t0"])
        vx, vy = _speed_at(kin, x, pre), _speed_at(kin, y, pre)
        if vy > vx:
            x, y, vx, vy = y, x, vy, vx
        if vx < MOVING_V or vy > AT_REST_V:
            continue
        s, e, a, b = _span(idx, ts, ts[pre], g.get("t_seen", g["t0"]))
        params = {"object_details": {x: _detail(trace, a, b, x, "moving object", speed=round(vx, 1)),
                                     y: _detail(trace, a, b, y, "stationary object", speed=round(vy, 1))},
                  "t": round(g["t0"], 4), "impact_speed": round(vx, 1)}
        out.append({"label": "moving object hits stationary object", "start_timestep": s, "end_timestep": e,
                    "parameters": params})
    return out
