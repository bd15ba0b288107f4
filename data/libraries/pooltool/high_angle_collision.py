"""high angle collision: a thin cut, where the striking ball meets the struck ball far from head-on
(cut angle between 45 and 90 degrees between its velocity and the line of centres at contact).

Uses the merged `physics_ball_ball` collisions; contact positions are the last timestep's positions
advanced by the recorded velocities to the contact time."""

def _clock(trace):
    """Timestep indices and times, in order."""
    idx, ts = [], []
    for s in trace.get("timesteps", []):
        idx.append(s.get("index", len(idx)))
        ts.append(float(s.get("t", 0.0)))
    return idx, ts


def _at(ts, t):
    """Position (in the timestep list) of the last timestep at or before time t."""
    lo, hi = 0, len(ts) - 1
    if t <= ts[0]:
        return 0
    if t >= ts[hi]:
        return hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ts[mid] <= t:
            lo = mid
        else:
            hi = mid
    return lo


def _span(idx, ts, t0, t1=None):
    """The narrowest inclusive step span covering times t0..t1: from the last step at or before t0 to the
    first step at or after t1 (one step when an instant falls exactly on a step)."""
    if t1 is None:
        t1 = t0
    a = _at(ts, t0)
    b = _at(ts, t1)
    if ts[b] < t1 and b + 1 < len(ts):
        b += 1
    return idx[a], idx[b], a, b


def _events(trace, kinds):
    """(t, payload) of events of the given kinds, in time order."""
    out = []
    for e in trace.get("events", []):
        if e.get("kind") in kinds and e.get("t") is not None:
            out.append((float(e["t"]), e.get("payload") or {}))
    out.sort(key=lambda x: x[0])
    return out


def _state(trace, k, bid):
    """The object dict of ball `bid` at timestep position k, or None."""
    for o in trace["timesteps"][k].get("objects", []):
        if str(o.get("ball_id")) == bid:
            return o
    return None


def _xy(o):
    p = (o or {}).get("position") or (0.0, 0.0)
    return [round(float(p[0]), 4), round(float(p[1]), 4)]


def _speed(o):
    v = (o or {}).get("velocity") or (0.0, 0.0)
    return (float(v[0]) ** 2 + float(v[1]) ** 2) ** 0.5


def _detail(trace, a, b, bid, role, **extra):
    """object_details entry: role, identity, and where the ball is when the pattern starts and ends."""
    d = {"role": role, "ball_id": bid, "kind": "ball",
         "start_position": _xy(_state(trace, a, bid)), "end_position": _xy(_state(trace, b, bid))}
    d.update(extra)
    return d

MERGE_S = 0.05


def _merge(events, key):
    """Merges events with the same key closer than MERGE_S seconds (a chattering contact is one
    collision). Returns groups {key, t0, t1, n, payloads} in time order."""
    last, out = {}, []
    for t, p in events:
        k = key(p)
        if k is None:
            continue
        g = last.get(k)
        if g is not None and t - g["t1"] <= MERGE_S:
            g["t1"] = t
            g["n"] += 1
            g["payloads"].append(p)
        else:
            g = {"key": k, "t0": t, "t1": t, "n": 1, "payloads": [p]}
            last[k] = g
            out.append(g)
    return out

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
