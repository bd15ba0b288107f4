"""airborne motion: a dynamic body flies touching nothing (no contact episode holds it), moving at at
least MOVING_V px/s for at least MIN_S."""

MOVING_V = 10.0
MIN_S = 0.2


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    contacts = _contacts(trace)
    out = []
    for oid, m in sorted(_kin(trace).items()):
        flags = [not _in_contact(contacts, oid, ts[k]) and (v[0] ** 2 + v[1] ** 2) ** 0.5 >= MOVING_V
                 for k, v in zip(m["k"], m["v"])]
        for i, j in _runs(m["k"], ts, flags, MIN_S):
            a, b = m["k"][i], m["k"][j]
            out.append({"label": "airborne motion", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {oid: _detail(trace, a, b, oid, "airborne object")},
                                       "duration_s": round(ts[b] - ts[a], 3)}})
    return out
