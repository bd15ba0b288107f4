"""rolling object: a ball moves at at least MOVING_V px/s while touching something, its spin matching its
speed (|angular velocity| x radius within ROLL_TOL of the speed), for at least MIN_S."""

MOVING_V = 10.0
ROLL_TOL = 0.25
MIN_S = 0.3


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    contacts = _contacts(trace)
    out = []
    for oid, m in sorted(_kin(trace).items()):
        if m["o"][0].get("shape") != "ball":
            continue
        r = float(m["o"][0].get("diameter", 0.0)) / 2.0
        flags = []
        for k, v, o in zip(m["k"], m["v"], m["o"]):
            sp = (v[0] ** 2 + v[1] ** 2) ** 0.5
            w = abs(float(o.get("angular_velocity") or 0.0)) * r
            flags.append(sp >= MOVING_V and abs(w - sp) <= ROLL_TOL * sp and bool(_in_contact(contacts, oid, ts[k])))
        for i, j in _runs(m["k"], ts, flags, MIN_S):
            a, b = m["k"][i], m["k"][j]
            out.append({"label": "rolling object", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {oid: _detail(trace, a, b, oid, "rolling object")},
                                       "distance_px": round(abs(float(m["o"][j]["x"]) - float(m["o"][i]["x"])), 1)}})
    return out
