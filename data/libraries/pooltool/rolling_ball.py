"""rolling ball: a ball rolls without slipping, from its sliding-to-rolling transition until its next
event (a collision, a cushion, a pocket, stopping or spinning in place).

One pattern per episode, not per timestep. From the event log when there is one, else from runs of
`motion_state == "rolling"` in the timesteps. A roll shorter than
the frame spacing still gets the two steps around it (the narrowest span that holds it)."""


MERGE_S = 0.05


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    out = []
    for bid, t0, t1 in _episodes(trace, ("physics_sliding_rolling",), None, "rolling"):
        if t1 <= t0:
            continue
        s, e, a, b = _span(idx, ts, t0, t1)
        speed = _speed(_state(trace, min(a + 1, b), bid))
        out.append({"label": "rolling ball", "start_timestep": s, "end_timestep": e,
                    "parameters": {"object_details": {bid: _detail(trace, a, b, bid, "rolling ball")},
                                   "t_start": round(t0, 4), "t_end": round(t1, 4),
                                   "start_speed": round(speed, 4)}})
    return out
