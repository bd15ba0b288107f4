//! Table geometry: linear cushion segments, circular jaw segments and pockets
//! (docs/envs/pool.md §P4), loaded from `pooltool_table.json` or from the
//! `table` block of a `pooltool-trace/1` file. Keeps the documents' key order, which is
//! pooltool's dict order (it only matters for exact-time ties).

use serde::Deserialize;
use serde::de::{Deserializer, MapAccess, Visitor};
use std::fmt;
use std::marker::PhantomData;

use super::error::{PoolError, Result};
use super::vec3::{self, V3};

/// Which side of a linear cushion's line is checked for contact (pooltool `LinearCushionType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CushionDirection {
    /// contact where l·r + l0 = −R‖l‖
    Side1,
    /// contact where l·r + l0 = +R‖l‖
    Side2,
    /// both sides
    Both,
}

/// A straight cushion segment at cushion height (pooltool `LinearCushionSegment`).
#[derive(Debug, Clone)]
pub struct LinearCushion {
    /// Segment id (`"3"`, `"12"`, …)
    pub id: String,
    /// First end point (m)
    pub p1: V3,
    /// Second end point (m)
    pub p2: V3,
    /// Which side is checked for contact
    pub direction: CushionDirection,
    /// general-form line coefficients `lx·x + ly·y + l0 = 0`
    pub lx: f64,
    /// Line coefficient of y
    pub ly: f64,
    /// Line constant
    pub l0: f64,
    /// `(p2 − p1)/|p2 − p1|`
    pub unit_axis: V3,
    /// `unit(lx, ly, 0)` (arbitrarily directed)
    pub normal: V3,
}

impl LinearCushion {
    /// A segment from p1 to p2; errors on a degenerate segment.
    pub fn new(id: String, p1: V3, p2: V3, direction: CushionDirection) -> Result<Self> {
        if !vec3::is_finite(p1) || !vec3::is_finite(p2) || (p1[0] == p2[0] && p1[1] == p2[1]) {
            return Err(PoolError::Data(format!("degenerate linear cushion {id}")));
        }
        let (p1x, p1y) = (p1[0], p1[1]);
        let (p2x, p2y) = (p2[0], p2[1]);
        let vertical = (p2x - p1x) == 0.0;
        let lx = if vertical {
            1.0
        } else {
            -(p2y - p1y) / (p2x - p1x)
        };
        let ly = if vertical { 0.0 } else { 1.0 };
        let l0 = if vertical {
            -p1x
        } else {
            (p2y - p1y) / (p2x - p1x) * p1x - p1y
        };
        let axis = vec3::sub(p2, p1);
        let n = vec3::norm(axis);
        let unit_axis = [axis[0] / n, axis[1] / n, axis[2] / n];
        let normal = vec3::unit([lx, ly, 0.0]);
        Ok(LinearCushion {
            id,
            p1,
            p2,
            direction,
            lx,
            ly,
            l0,
            unit_axis,
            normal,
        })
    }

    /// 3D unit normal from the cushion edge line to `xyz` (pooltool `get_normal_3d`).
    pub fn normal_3d(&self, xyz: V3) -> V3 {
        let r = vec3::sub(xyz, self.p1);
        let d = vec3::dot(r, self.unit_axis);
        vec3::unit(vec3::sub(r, vec3::scale(self.unit_axis, d)))
    }

    /// Distance from the point `(x, y)` to the segment (2D), for conservative pruning.
    pub fn distance_2d(&self, x: f64, y: f64) -> f64 {
        let (ax, ay) = (self.p2[0] - self.p1[0], self.p2[1] - self.p1[1]);
        let (px, py) = (x - self.p1[0], y - self.p1[1]);
        let l2 = ax * ax + ay * ay;
        let s = ((px * ax + py * ay) / l2).clamp(0.0, 1.0);
        let (dx, dy) = (px - s * ax, py - s * ay);
        (dx * dx + dy * dy).sqrt()
    }
}

/// A circular cushion segment ("jaw"/knuckle) at cushion height.
#[derive(Debug, Clone)]
pub struct CircularCushion {
    /// Jaw id (`"8t"`, …)
    pub id: String,
    /// Centre (m)
    pub center: V3,
    /// Radius (m)
    pub radius: f64,
}

impl CircularCushion {
    /// 3D unit normal from the jaw centre to `xyz` (pooltool `get_normal_3d`).
    pub fn normal_3d(&self, xyz: V3) -> V3 {
        vec3::unit(vec3::sub(xyz, self.center))
    }
}

/// A pocket: the ball is pocketed when its centre enters the circle.
#[derive(Debug, Clone)]
pub struct Pocket {
    /// Pocket id (`lb`, `lc`, `lt`, `rb`, `rc`, `rt`)
    pub id: String,
    /// Centre (m)
    pub center: V3,
    /// Radius (m)
    pub radius: f64,
    /// Depth (m)
    pub depth: f64,
}

/// The playing surface and its boundary.
#[derive(Debug, Clone)]
pub struct Table {
    /// playing-area width (x extent), m
    pub w: f64,
    /// playing-area length (y extent), m
    pub l: f64,
    /// Straight cushion segments, in file order
    pub linear: Vec<LinearCushion>,
    /// Jaws, in file order
    pub circular: Vec<CircularCushion>,
    /// Pockets, in file order
    pub pockets: Vec<Pocket>,
}

// ---- JSON ---------------------------------------------------------------------------

#[derive(Deserialize)]
struct LinearJson {
    p1: V3,
    p2: V3,
    direction: i64,
}
#[derive(Deserialize)]
struct CircularJson {
    center: V3,
    radius: f64,
}
#[derive(Deserialize)]
struct PocketJson {
    center: V3,
    radius: f64,
    depth: f64,
}

/// A JSON object read as an ordered list of (key, value) pairs.
struct Ordered<T>(Vec<(String, T)>);

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Ordered<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V<T>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = Ordered<T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a JSON object")
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                mut m: A,
            ) -> std::result::Result<Self::Value, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = m.next_entry::<String, T>()? {
                    out.push((k, v));
                }
                Ok(Ordered(out))
            }
        }
        d.deserialize_map(V(PhantomData))
    }
}

#[derive(Deserialize)]
struct TableJson {
    w: f64,
    l: f64,
    #[serde(alias = "linear_cushions")]
    linear: Ordered<LinearJson>,
    #[serde(alias = "circular_cushions")]
    circular: Ordered<CircularJson>,
    pockets: Ordered<PocketJson>,
}

impl Table {
    /// Table from `pooltool_table.json` (keys `linear`/`circular`/`pockets`) or from a
    /// trace's `table` object (keys `linear_cushions`/`circular_cushions`/`pockets`).
    pub fn from_json_str(json: &str) -> Result<Table> {
        let t: TableJson = serde_json::from_str(json)?;
        Self::from_parsed(t)
    }

    /// Table from an already-parsed JSON value (e.g. `trace["table"]`).
    pub fn from_json_value(v: &serde_json::Value) -> Result<Table> {
        let t: TableJson = serde_json::from_value(v.clone())?;
        Self::from_parsed(t)
    }

    fn from_parsed(t: TableJson) -> Result<Table> {
        let mut linear = Vec::new();
        for (id, c) in t.linear.0 {
            let dir = match c.direction {
                0 => CushionDirection::Side1,
                1 => CushionDirection::Side2,
                2 => CushionDirection::Both,
                d => return Err(PoolError::Data(format!("cushion {id}: bad direction {d}"))),
            };
            linear.push(LinearCushion::new(id, c.p1, c.p2, dir)?);
        }
        let mut circular = Vec::new();
        for (id, c) in t.circular.0 {
            if c.radius.is_nan() || c.radius <= 0.0 || !vec3::is_finite(c.center) {
                return Err(PoolError::Data(format!("bad jaw {id}")));
            }
            circular.push(CircularCushion {
                id,
                center: c.center,
                radius: c.radius,
            });
        }
        let mut pockets = Vec::new();
        for (id, p) in t.pockets.0 {
            if p.radius.is_nan()
                || p.radius <= 0.0
                || !vec3::is_finite(p.center)
                || !p.depth.is_finite()
            {
                return Err(PoolError::Data(format!("bad pocket {id}")));
            }
            pockets.push(Pocket {
                id,
                center: p.center,
                radius: p.radius,
                depth: p.depth,
            });
        }
        if !(t.w > 0.0 && t.l > 0.0) {
            return Err(PoolError::Data("table w and l must be > 0".into()));
        }
        Ok(Table {
            w: t.w,
            l: t.l,
            linear,
            circular,
            pockets,
        })
    }

    /// pooltool's default "7 Ft Showood" pocket table.
    pub fn default_7ft() -> Table {
        Self::from_json_str(super::params::DEFAULT_TABLE_JSON).expect("shipped table JSON is valid")
    }

    /// Cushion height (z of the first linear segment; 0 if none).
    pub fn cushion_height(&self) -> f64 {
        self.linear.first().map(|c| c.p1[2]).unwrap_or(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Source: docs/envs/pool.md §P4 (18 linear, 12 jaws, 6 pockets) and the
    /// precomputed lx/ly/l0 stored in pooltool_table.json by dump_geom.py (rounded to 1e-6 there).
    #[test]
    fn default_table_geometry() {
        let t = Table::default_7ft();
        assert_eq!(t.linear.len(), 18);
        assert_eq!(t.circular.len(), 12);
        assert_eq!(t.pockets.len(), 6);
        assert_eq!(t.linear[0].id, "3");
        let v: serde_json::Value =
            serde_json::from_str(super::super::params::DEFAULT_TABLE_JSON).unwrap();
        for c in &t.linear {
            let j = &v["linear"][&c.id];
            assert!(
                (c.lx - j["lx"].as_f64().unwrap()).abs() < 1e-5,
                "lx {}",
                c.id
            );
            assert!(
                (c.ly - j["ly"].as_f64().unwrap()).abs() < 1e-5,
                "ly {}",
                c.id
            );
            assert!(
                (c.l0 - j["l0"].as_f64().unwrap()).abs() < 1e-5,
                "l0 {}",
                c.id
            );
        }
        assert!((t.cushion_height() - 0.036576).abs() < 1e-12);
        let rt = t.pockets.iter().find(|p| p.id == "rt").unwrap();
        assert_eq!(rt.radius, 0.062);
    }
}
