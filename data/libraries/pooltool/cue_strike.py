"""cue strike: the cue stick hits the cue ball.

Grounded in the event log (`physics_stick_ball`); the span is the narrowest step span holding the strike
time. object_details: the struck ball with its positions; parameters: the shot (V0, phi, theta, a, b) when
the trace records it (annotrace's strike payload, or a top-level `shot` as pooltool exporters write).
Without an event log (imported traces) the contacts are inferred from the recorded velocities
(`_kinematic`).
"""


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    out = []
    for t, p in _events(trace, ("physics_stick_ball",)):
        agents = p.get("agents") or ["cue_stick", "cue"]
        bid = str(p.get("ball") or agents[-1])
        s, e, a, b = _span(idx, ts, t)
        later = _at(ts, t + 0.2)
        params = {"object_details": {bid: _detail(trace, a, later, bid, "struck cue ball")}, "t": round(t, 4)}
        shot = _shot(trace, p)
        for k in ("V0", "phi", "theta", "a", "b"):
            if isinstance(shot.get(k), (int, float)):
                params[k] = round(float(shot[k]), 4)
        out.append({"label": "cue strike", "start_timestep": s, "end_timestep": e, "parameters": params})
    return out
