"""ball pocketed: a ball drops into a pocket.

Grounded in `physics_ball_pocket` events; the span holds the drop time.
Without an event log (imported traces) the contacts are inferred from the recorded velocities
(`_kinematic`).
"""


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    out = []
    for t, p in _events(trace, ("physics_ball_pocket",)):
        if p.get("ball") is None:
            continue
        bid = str(p["ball"])
        s, e, a, b = _span(idx, ts, t)
        before = max(a - 1, 0)
        details = {bid: _detail(trace, before, b, bid, "pocketed ball")}
        pocket = str(p.get("pocket"))
        details["pocket " + pocket] = {"role": "pocket", "pocket_id": pocket}
        out.append({"label": "ball pocketed", "start_timestep": s, "end_timestep": e,
                    "parameters": {"object_details": details, "t": round(t, 4), "pocket": pocket}})
    return out
