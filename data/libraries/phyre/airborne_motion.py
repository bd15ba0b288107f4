"""airborne motion: a body flies touching nothing: a maximal run of frames in which no contact episode
holds it, lasting at least MIN_S, over which it moves at least MOVING_V px/s on average (path length
from its positions over the run's duration). The whole run counts, so a flight that starts from rest
(a body released in mid-air, a ball at the top of a vertical throw) is one pattern, not cut where its
speed is still low. Bodies that never move (walls, static bars) are never airborne."""

MOVING_V = 10.0
MIN_S = 0.2


def _path(objs, i, j):
    total = 0.0
    for n in range(i, j):
        a, b = objs[n], objs[n + 1]
        total += ((float(b["x"]) - float(a["x"])) ** 2 + (float(b["y"]) - float(a["y"])) ** 2) ** 0.5
    return total


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    contacts = _contacts(trace)
    kin = _kin(trace)
    out = []
    for oid, m in sorted(kin.items()):
        if _is_static(kin, oid):
            continue
        mine = [g for g in contacts if oid in g["pair"]]  # this body's contacts, in their order
        free = [not _in_contact(mine, oid, ts[k]) for k in m["k"]]
        # Maximal runs: a frame in contact ends a flight, however short the contact.
        for i, j in _runs(m["k"], ts, free, MIN_S, gap=0.0):
            a, b = m["k"][i], m["k"][j]
            duration = ts[b] - ts[a]
            if _path(m["o"], i, j) < MOVING_V * duration:
                continue
            out.append({"label": "airborne motion", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {oid: _detail(trace, a, b, oid, "airborne object")},
                                       "duration_s": round(duration, 3)}})
    return out
