"""grid cell transition: a dynamic body's centre crosses from one cell of the 8 x 8 action grid (CELL =
32 px cells of the 256 px scene) to another. One pattern per crossing, spanning the two frames; cells
are (column, row) from the bottom left."""

CELL = 32.0


def _cell(o):
    return (min(7, max(0, int(float(o["x"]) // CELL))), min(7, max(0, int(float(o["y"]) // CELL))))


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for oid, m in sorted(kin.items()):
        if _is_static(kin, oid):
            continue
        for n in range(1, len(m["o"])):
            c0, c1 = _cell(m["o"][n - 1]), _cell(m["o"][n])
            if c0 == c1:
                continue
            a, b = m["k"][n - 1], m["k"][n]
            out.append({"label": "grid cell transition", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {oid: _detail(trace, a, b, oid, "moving object",
                                                                       from_cell=list(c0), to_cell=list(c1))}}})
    return out
