"""spin shot: the cue ball is struck off centre, so it carries follow, draw or side spin.

From the strike's tip offsets (`a` side, `b` vertical, as fractions of the radius) in the stick-ball event
or the trace's top-level `shot` when present, else from the cue ball's angular velocity just after the strike compared with natural roll.
Offsets below 0.2 R are a centre-ball hit. The span runs from the strike until the cue ball first rolls
(while it slides, the spin is acting)."""


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
        shot = _shot(trace, p)
        if isinstance(shot.get("a"), (int, float)) and isinstance(shot.get("b"), (int, float)):
            side, vert = float(shot["a"]), float(shot["b"])
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
