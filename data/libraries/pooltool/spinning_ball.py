"""spinning ball: a ball spins in place about the vertical axis (pooltool's `spinning` state), from its
rolling-to-spinning transition until it stops or is hit."""

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


def _balls_of(kind, p):
    """Ball ids an event involves (cushion and pocket ids are not balls)."""
    if kind == "physics_ball_ball":
        return [str(a) for a in (p.get("agents") or [])[:2]]
    b = p.get("ball")
    return [str(b)] if b is not None else []


def _episodes(trace, starts, ends, state_name):
    """Per-ball episodes of a motion state, from the event log: an episode opens at an event of a kind in
    `starts` for the ball (unless one is open) and closes at the next event in `ends` for the ball, or at
    the end of the trace. Without an event log, runs of `motion_state == state_name` in the timesteps."""
    evs = []
    for e in trace.get("events", []):
        k = e.get("kind", "")
        if k.startswith("physics_") and e.get("t") is not None:
            evs.append((float(e["t"]), k, e.get("payload") or {}))
    evs.sort(key=lambda x: x[0])
    out = []
    if evs:
        t_end = float(trace["timesteps"][-1].get("t", 0.0))
        open_ = {}
        for t, k, p in evs:
            for b in _balls_of(k, p):
                if b in open_ and (ends is None or k in ends) and t > open_[b]:
                    out.append((b, open_.pop(b), t))
                if k in starts and b not in open_:
                    open_[b] = t
        for b, t0 in open_.items():
            out.append((b, t0, t_end))
        out.sort(key=lambda x: (x[1], x[0]))
        return out
    # From frames, the state changed somewhere between two samples: an episode runs from the sample
    # before its first frame to the first sample after it, the narrowest span that holds both changes.
    runs = {}
    t_prev = None
    for s in trace.get("timesteps", []):
        t = float(s.get("t", 0.0))
        seen = set()
        for o in s.get("objects", []):
            b = str(o.get("ball_id"))
            seen.add(b)
            if o.get("motion_state") == state_name:
                if b not in runs:
                    runs[b] = [t if t_prev is None else t_prev, t]
                runs[b][1] = t
            elif b in runs:
                t0, t1 = runs.pop(b)
                out.append((b, t0, t))
        for b in [b for b in runs if b not in seen]:
            t0, t1 = runs.pop(b)
            out.append((b, t0, t))
        t_prev = t
    for b, (t0, t1) in runs.items():
        out.append((b, t0, t1))
    out.sort(key=lambda x: (x[1], x[0]))
    return out

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
