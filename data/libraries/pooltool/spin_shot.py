"""spin shot: the cue ball is struck off centre, so it carries follow, draw or side spin.

From the strike's tip offsets (`a` side, `b` vertical, as fractions of the radius) in the stick-ball event
when present, else from the cue ball's angular velocity just after the strike compared with natural roll.
Offsets below 0.2 R are a centre-ball hit. The span runs from the strike until the cue ball first rolls
(while it slides, the spin is acting)."""

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

THRESHOLD = 0.2


def _spin_from_state(o):
    v = o.get("velocity") or (0.0, 0.0, 0.0)
    w = o.get("angular_velocity") or (0.0, 0.0, 0.0)
    r = float(o.get("radius") or 0.028575)
    sp = (float(v[0]) ** 2 + float(v[1]) ** 2) ** 0.5
    if sp < 1e-6:
        return 0.0, 0.0
    ux, uy = float(v[0]) / sp, float(v[1]) / sp
    # Natural roll: w = z x v / R. Topspin along the heading is -(w x z)·u scaled by R/|v|.
    top = (float(w[0]) * -uy + float(w[1]) * ux) * r / sp
    side = float(w[2]) * r / sp
    return side, top - 1.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    rolls = _events(trace, ("physics_sliding_rolling",))
    out = []
    for t, p in _events(trace, ("physics_stick_ball",)):
        bid = str(p.get("ball") or (p.get("agents") or ["", "cue"])[-1])
        if isinstance(p.get("a"), (int, float)) and isinstance(p.get("b"), (int, float)):
            side, vert = float(p["a"]), float(p["b"])
        else:
            o = _state(trace, min(_at(ts, t) + 1, len(ts) - 1), bid)
            side, vert = _spin_from_state(o or {})
        if (side * side + vert * vert) ** 0.5 < THRESHOLD:
            continue
        kinds = []
        if vert >= THRESHOLD / 2:
            kinds.append("follow")
        elif vert <= -THRESHOLD / 2:
            kinds.append("draw")
        if abs(side) >= THRESHOLD / 2:
            kinds.append("right english" if side > 0 else "left english")
        t1 = next((tr for tr, q in rolls if tr > t and str(q.get("ball")) == bid), t)
        s, e, a, b = _span(idx, ts, t, t1)
        out.append({"label": "spin shot", "start_timestep": s, "end_timestep": e,
                    "parameters": {"object_details": {bid: _detail(trace, a, b, bid, "spinning cue ball")},
                                   "spin": " and ".join(kinds) or "spin",
                                   "side_offset": round(side, 3), "vertical_offset": round(vert, 3)}})
    return out
