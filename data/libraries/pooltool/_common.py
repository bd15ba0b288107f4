"""Prelude: Helpers every built-in pooltool detector uses: the timestep clock, step lookup by time, the event log, ball states, positions, speeds and object details.

library.toml prepends it to the detectors that list it; it defines no find_pattern."""


def _clock(trace):
    """Timestep indices and times, in order."""
    steps = trace.get("timesteps", [])
    try:
        # Every step has both (the usual case): two comprehensions, no call per step.
        return [s["index"] for s in steps], [float(s["t"]) for s in steps]
    except (KeyError, TypeError):
        pass
    # A step without its index (its position) or its time (0).
    idx, ts = [], []
    for s in steps:
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


CUSHION_KINDS = ("physics_ball_linear_cushion", "physics_ball_circular_cushion")


def _roles(kind, p):
    """(balls, other id) of a pooltool event, from `payload.agents` by pooltool's id conventions: the
    order of the ids depends on the event kind, not on what the ids look like (cushion segments "1".."18"
    look like ball ids; jaws are "1t".., pockets "lb".."rt"). stick_ball: (cue stick, ball); ball_ball:
    (ball, ball); ball_*_cushion: (ball, cushion); ball_pocket: (ball, pocket); motion transitions:
    (ball,). Falls back to annotrace's extra `ball` / `cushion` / `pocket` fields when agents are missing."""
    ag = [str(a) for a in (p.get("agents") or [])]
    other = None
    if kind == "physics_stick_ball":
        balls = ag[1:2] or ag[:1]
    elif kind == "physics_ball_ball":
        balls = ag[:2]
    else:
        balls = ag[:1]
        if kind in CUSHION_KINDS or kind == "physics_ball_pocket":
            other = ag[1] if len(ag) > 1 else None
    if not balls and p.get("ball") is not None:
        balls = [str(p["ball"])]
    if other is None:
        o = p.get("cushion") if kind in CUSHION_KINDS else p.get("pocket")
        other = str(o) if o is not None else None
    return balls, other


def _events(trace, kinds):
    """(t, payload) of events of the given kinds, in time order. Every payload is a copy with `ball`
    (the first ball, `_roles`), and `cushion` / `pocket` where the kind has one, filled in from
    `payload.agents`, so detectors read one shape whatever wrote the trace."""
    out = []
    for e in trace.get("events", []):
        k = e.get("kind")
        if k in kinds and e.get("t") is not None:
            p = dict(e.get("payload") or {})
            balls, other = _roles(k, p)
            if balls and k != "physics_ball_ball":
                p["ball"] = balls[0]
            if other is not None:
                p["cushion" if k in CUSHION_KINDS else "pocket"] = other
            out.append((float(e["t"]), p))
    out.sort(key=lambda x: x[0])
    return out


def _shot(trace, p):
    """The cue parameters (V0, phi, theta, a, b) of a strike: its event payload when it carries them
    (annotrace's simulator), else the trace's top-level `shot` object (pooltool exporters), else {}."""
    if any(isinstance(p.get(k), (int, float)) for k in ("V0", "a", "b")):
        return p
    shot = trace.get("shot")
    return shot if isinstance(shot, dict) else {}


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
