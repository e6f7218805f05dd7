//! A bag's transform tree (`/tf`, `/tf_static`, an odometry topic): each frame has one parent;
//! a static edge holds one transform, a dynamic edge its stamped transforms, interpolated
//! (translation linearly, rotation by slerp) between the two around a time and never
//! extrapolated, as tf2 does. Frame ids lose a leading `/` (ROS 1 style), as in tf2.

use super::cdr::Transform;
use glam::{DMat4, DQuat, DVec3};
use std::collections::{BTreeSet, HashMap};

/// The frame id as tf2 compares it.
pub fn frame_name(id: &str) -> &str {
    id.strip_prefix('/').unwrap_or(id)
}

/// How a frame hangs from its parent.
#[derive(Debug)]
struct Edge {
    parent: String,
    /// Static: one entry (time ignored). Dynamic: sorted by time, one per time.
    stamped: Vec<(i64, DQuat, DVec3)>,
    is_static: bool,
}

/// The transform tree.
#[derive(Debug, Default)]
pub struct Tree {
    edges: HashMap<String, Edge>,
}

/// Why a transform cannot be had.
#[derive(Debug, PartialEq)]
pub enum Miss {
    /// The two frames are not connected (or a frame is unknown).
    NoChain,
    /// Connected, but an edge of the chain has no transforms around the time.
    OutsideTime,
}

impl Tree {
    /// Adds `t` (a static edge replaces the one before; a dynamic one is appended). A frame
    /// given two parents, or its own parent, is an error.
    pub fn add(&mut self, t: &Transform, is_static: bool) -> Result<(), String> {
        let (parent, child) = (frame_name(&t.parent), frame_name(&t.child));
        if parent == child {
            return Err(format!("frame '{child}' is given as its own parent"));
        }
        if !t.translation.is_finite() || t.translation.abs().max_element() > crate::input::MAX_COORDINATE_M {
            return Err(format!("the transform '{parent}' -> '{child}' moves by {}", t.translation));
        }
        let e = self.edges.entry(child.to_string()).or_insert_with(|| Edge { parent: parent.to_string(), stamped: Vec::new(), is_static });
        if e.parent != parent {
            return Err(format!("frame '{child}' has two parents, '{}' and '{parent}'", e.parent));
        }
        if e.is_static != is_static {
            return Err(format!("the transform '{parent}' -> '{child}' is both static and dynamic"));
        }
        if is_static {
            e.stamped.clear();
        }
        e.stamped.push((t.stamp_ns, t.rotation, t.translation));
        Ok(())
    }

    /// Sorts the dynamic edges by time (a later message at the same time wins).
    pub fn finish(&mut self) {
        for e in self.edges.values_mut().filter(|e| !e.is_static) {
            e.stamped.reverse();
            e.stamped.sort_by_key(|s| s.0);
            e.stamped.dedup_by_key(|s| s.0);
        }
    }

    /// Every frame named by an edge.
    pub fn frames(&self) -> BTreeSet<&str> {
        self.edges.iter().flat_map(|(c, e)| [c.as_str(), e.parent.as_str()]).collect()
    }

    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    /// `frame` and its ancestors up to the root.
    fn ancestors<'a>(&'a self, frame: &'a str) -> Vec<&'a str> {
        let mut out = vec![frame];
        let mut at = frame;
        while let Some(e) = self.edges.get(at) {
            at = &e.parent;
            if out.contains(&at) {
                break; // a cycle: never closes into a chain
            }
            out.push(at);
        }
        out
    }

    /// The edge `parent_from_child` of `child` at time `t`.
    fn edge_at(&self, child: &str, t: i64) -> Option<DMat4> {
        let e = &self.edges[child];
        let s = &e.stamped;
        let m = |q: DQuat, v: DVec3| DMat4::from_rotation_translation(q, v);
        if e.is_static {
            return s.first().map(|&(_, q, v)| m(q, v));
        }
        let i = s.partition_point(|x| x.0 < t);
        if i < s.len() && s[i].0 == t {
            return Some(m(s[i].1, s[i].2));
        }
        if i == 0 || i == s.len() {
            return None;
        }
        let (a, b) = (s[i - 1], s[i]);
        let f = (t - a.0) as f64 / (b.0 - a.0) as f64;
        Some(m(a.1.slerp(b.1, f), a.2.lerp(b.2, f)))
    }

    /// `ancestor_from_frame` along `chain` (frame first, ancestor last) at `t`.
    fn up(&self, chain: &[&str], t: i64) -> Option<DMat4> {
        let mut acc = DMat4::IDENTITY;
        for c in &chain[..chain.len() - 1] {
            acc = self.edge_at(c, t)? * acc;
        }
        Some(acc)
    }

    /// `target_from_source` at time `t`.
    pub fn lookup(&self, target: &str, source: &str, t: i64) -> Result<DMat4, Miss> {
        let (target, source) = (frame_name(target), frame_name(source));
        let a = self.ancestors(source);
        let b = self.ancestors(target);
        let Some(ia) = a.iter().position(|f| b.contains(f)) else {
            return Err(Miss::NoChain);
        };
        let ib = b.iter().position(|f| *f == a[ia]).expect("common");
        let up_a = self.up(&a[..=ia], t).ok_or(Miss::OutsideTime)?;
        let up_b = self.up(&b[..=ib], t).ok_or(Miss::OutsideTime)?;
        Ok(up_b.inverse() * up_a)
    }

    /// True when `target` and `source` are connected.
    pub fn connected(&self, target: &str, source: &str) -> bool {
        let b = self.ancestors(frame_name(target));
        self.ancestors(frame_name(source)).iter().any(|f| b.contains(f))
    }
}
