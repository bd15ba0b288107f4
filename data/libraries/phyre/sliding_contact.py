"""sliding contact: a body moves at at least MOVING_V px/s while touching another without rolling (a
non-ball, or a ball whose spin does not match its speed within ROLL_TOL), for at least MIN_S."""

MOVING_V = 10.0
ROLL_TOL = 0.25
MIN_S = 0.2


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    contacts = _contacts(trace)
    out = []
    for oid, m in sorted(_kin(trace).items()):
        r = float(m["o"][0].get("diameter", 0.0)) / 2.0
        ball = m["o"][0].get("shape") == "ball"
        flags, partner = [], []
        # The contacts this object is part of, in their order; read only at steps where it moves fast
        # enough to be flagged (a partner is read only at a flagged step, where a run starts).
        mine = [g for g in contacts if oid in g["pair"]]
        for k, v, o in zip(m["k"], m["v"], m["o"]):
            sp = (v[0] ** 2 + v[1] ** 2) ** 0.5
            w = abs(float(o.get("angular_velocity") or 0.0)) * r
            touching = _in_contact(mine, oid, ts[k]) if sp >= MOVING_V else None
            partner.append(touching[0]["pair"] if touching else None)
            flags.append(sp >= MOVING_V and bool(touching) and not (ball and abs(w - sp) <= ROLL_TOL * sp))
        for i, j in _runs(m["k"], ts, flags, MIN_S):
            a, b = m["k"][i], m["k"][j]
            det = {oid: _detail(trace, a, b, oid, "sliding object")}
            p = partner[i]
            if p:
                other = p[0] if p[1] == oid else p[1]
                det[other] = _detail(trace, a, b, other, "surface")
            out.append({"label": "sliding contact", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": det, "duration_s": round(ts[b] - ts[a], 3)}})
    return out
