"""sliding contact: an object moves along the surface of another while touching it.

Within a contact episode (chatter merged), the runs of frames in which the velocity of the dynamic
object relative to the other, along the contact tangent, is at least SLIDE_V px/s, lasting at least
MIN_S. The tangent is perpendicular to the contact normal (closest points of the two capsules). When both
are dynamic the faster one is the sliding object. Parameters: mean tangential speed and the distance
slid (px).
"""

SLIDE_V = 15.0
MIN_S = 0.1


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for g in _contacts(trace):
        x, y = g["pair"]
        if x not in kin or y not in kin:
            continue
        a0, b0 = _at(ts, g["t0"]), _at(ts, g["t1"])
        ks, flags, tang = [], [], []
        for k in range(a0, b0 + 1):
            ox, oy = _obj_at(trace, k, x), _obj_at(trace, k, y)
            if ox is None or oy is None:
                break
            vx, vy = _vel(kin, x, k), _vel(kin, y, k)
            rx, ry = vx[0] - vy[0], vx[1] - vy[1]
            nx, ny = _normal(oy, ox)
            vt = abs(-ny * rx + nx * ry)
            ks.append(k)
            tang.append(vt)
            flags.append(vt >= SLIDE_V)
        for i, j in _runs(ks, ts, flags, MIN_S):
            a, b = ks[i], ks[j]
            sx, sy = _speed_at(kin, x, a), _speed_at(kin, y, a)
            slider, surface = (x, y) if sx >= sy else (y, x)
            mean = sum(tang[i:j + 1]) / (j - i + 1)
            params = {"object_details": {slider: _detail(trace, a, b, slider, "sliding object"),
                                         surface: _detail(trace, a, b, surface, "surface")},
                      "mean_tangential_speed": round(mean, 1),
                      "distance_px": round(mean * (ts[b] - ts[a]), 1)}
            out.append({"label": "sliding contact", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": params})
    return out
