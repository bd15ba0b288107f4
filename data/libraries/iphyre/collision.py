"""collision: two objects come into contact.

Grounded in `contact_begin` events; a pair's contact that begins again within 50 ms of its end is the
same collision (chatter), so the pattern spans the first begin and its re-begins. Without an event log
the contacts come from the capsule geometry of the frames (`_contacts`). Roles: the object moving faster
in the frame before the contact is the striking object; speeds are in px/s. Contacts that begin with
both objects slower than MOVING_V (objects placed touching, settling at the start) keep their pattern
with roles saying so.
"""

MOVING_V = 1.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for g in _contacts(trace):
        x, y = g["pair"]
        burst = [t for t in g["begins"] if t - g["t0"] <= 10 * MERGE_S]
        s, e, a, b = _span(idx, ts, g["t0"], max(burst[-1], g.get("t_seen", g["t0"])))
        before = a if "t_seen" in g else max(a - 1, 0)
        vx, vy = _speed_at(kin, x, before), _speed_at(kin, y, before)
        if vy > vx:
            x, y, vx, vy = y, x, vy, vx
        moving = vx >= MOVING_V
        params = {"object_details": {x: _detail(trace, a, b, x, "striking object" if moving else "object settling into contact",
                                                speed_before=round(vx, 2)),
                                     y: _detail(trace, a, b, y, "struck object" if moving else "object settled on",
                                                speed_before=round(vy, 2))},
                  "t": round(g["t0"], 4), "contacts": len(g["begins"]),
                  "contact_duration_s": round(g["t1"] - g["t0"], 4)}
        out.append({"label": "collision", "start_timestep": s, "end_timestep": e, "parameters": params})
    return out
