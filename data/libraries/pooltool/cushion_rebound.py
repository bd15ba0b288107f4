"""cushion rebound: a ball bounces off a cushion (a straight rail or a pocket jaw).

Grounded in `physics_ball_linear_cushion` / `physics_ball_circular_cushion` events; contacts of the same
ball closer than 50 ms (rail then jaw) are one rebound."""

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

def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    evs = _events(trace, ("physics_ball_linear_cushion", "physics_ball_circular_cushion"))
    out = []
    for g in _merge(evs, lambda p: str(p["ball"]) if p.get("ball") is not None else None):
        bid = g["key"]
        s, e, a, b = _span(idx, ts, g["t0"], g["t1"])
        cushions = [str(p.get("cushion")) for p in g["payloads"]]
        details = {bid: _detail(trace, a, b, bid, "rebounding ball")}
        details["cushion " + cushions[0]] = {"role": "cushion", "cushion_id": cushions[0]}
        params = {"object_details": details, "t": round(g["t0"], 4), "cushions": cushions}
        sp = [float(p["speed"]) for p in g["payloads"] if isinstance(p.get("speed"), (int, float))]
        if sp:
            params["speed_in"] = round(sp[0], 4)
        out.append({"label": "cushion rebound", "start_timestep": s, "end_timestep": e, "parameters": params})
    return out
