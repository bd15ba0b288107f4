"""cushion rebound: a ball bounces off a cushion (a straight rail or a pocket jaw).

Grounded in `physics_ball_linear_cushion` / `physics_ball_circular_cushion` events; contacts of the same
ball closer than 50 ms (rail then jaw) are one rebound.
Without an event log (imported traces) the contacts are inferred from the recorded velocities
(`_kinematic`).
"""


MERGE_S = 0.05


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
