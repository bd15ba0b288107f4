"""high angle collision: a thin cut, where the striking ball meets the struck ball far from head-on
(cut angle between 45 and 90 degrees between its velocity and the line of centres at contact).

Uses the merged `physics_ball_ball` collisions; contact positions are the last timestep's positions
advanced by the recorded velocities to the contact time."""


MERGE_S = 0.05


CUT_DEG = 45.0


def _cos(x):
    s, term = 1.0, 1.0
    for n in range(1, 12):
        term *= -x * x / ((2 * n - 1) * (2 * n))
        s += term
    return s


def _acos_deg(c):
    c = max(-1.0, min(1.0, c))
    lo, hi = 0.0, 3.141592653589793
    for _ in range(40):
        mid = (lo + hi) / 2
        if _cos(mid) > c:
            lo = mid
        else:
            hi = mid
    return lo * 180.0 / 3.141592653589793


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
        ox, oy = _state(trace, a, x), _state(trace, a, y)
        if ox is None or oy is None:
            continue
        if _speed(oy) > _speed(ox):
            x, y, ox, oy = y, x, oy, ox
        dt = g["t0"] - ts[a]
        px = [ox["position"][i] + ox["velocity"][i] * dt for i in (0, 1)]
        py = [oy["position"][i] + oy["velocity"][i] * dt for i in (0, 1)]
        n = [py[0] - px[0], py[1] - px[1]]
        v = [ox["velocity"][0] - oy["velocity"][0], ox["velocity"][1] - oy["velocity"][1]]
        nn = (n[0] ** 2 + n[1] ** 2) ** 0.5
        vn = (v[0] ** 2 + v[1] ** 2) ** 0.5
        if nn < 1e-9 or vn < 1e-6:
            continue
        angle = _acos_deg((n[0] * v[0] + n[1] * v[1]) / (nn * vn))
        if angle < CUT_DEG or angle >= 90.0:
            continue  # head-on-ish, or the balls are not approaching (a stale estimate inside a cluster)
        out.append({"label": "high angle collision", "start_timestep": s, "end_timestep": e,
                    "parameters": {"object_details": {x: _detail(trace, a, b, x, "striking ball"),
                                                      y: _detail(trace, a, b, y, "struck ball")},
                                   "cut_angle_deg": round(angle, 1), "t": round(g["t0"], 4)}})
    return out
