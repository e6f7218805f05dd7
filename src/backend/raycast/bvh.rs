//! Construction of the two-level BVH that `traverse.rs` casts through: one bottom-level tree
//! per mesh, built in parallel over meshes and, for big meshes, over subtrees (rayon). By
//! default a Morton LBVH (63-bit codes of the triangle box centres, one sort, split at the
//! highest differing bit, leaves of up to 4; ~3x faster to build than binned SAH for the
//! same cast time here), or binned SAH (`BOTTOM_SAH`: 16 bins on the widest centroid axis,
//! leaves up to 8). One small top-level tree over the meshes (binned SAH, one mesh per leaf),
//! rebuilt per cast for a mesh filter (microseconds). Flat node arrays, f32 boxes padded
//! outward (1e-6 relative + 1 um) so that the conservative box test never culls a triangle
//! the f64 test hits. The build is deterministic; the hits never depend on the tree shape.
//!
//! The node layout and the per-mesh trees (`Blas`) are shared with the refit cache
//! (`refit.rs`), which keeps the trees across frames and only recomputes their boxes.

use crate::geometry::FrameGeometry;
use glam::{Vec3A, Vec4};
use rayon::prelude::*;

// ---------------------------------------------------------------------------------------------
// BVH
// ---------------------------------------------------------------------------------------------

/// Flat BVH node (32 bytes). Inner: `b == 0`, children at `a` and `a + 1`.
/// Bottom-level leaf: `a` = first slot, `b` = count | `CULL_BIT`. Top-level leaf: `a` = index
/// into `Bvh::meshes`, `b` = 1.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C)]
pub(super) struct Node {
    pub(super) lo: [f32; 3],
    pub(super) a: u32,
    pub(super) hi: [f32; 3],
    pub(super) b: u32,
}

pub(super) const CULL_BIT: u32 = 1 << 31;
pub(super) const COUNT_MASK: u32 = !CULL_BIT;

/// Bottom level: binned SAH (better trees, ~3x slower build) or Morton LBVH (default).
const BOTTOM_SAH: bool = false;
const BINS: usize = 16;
const MAX_LEAF: usize = 8;
/// Beyond this depth, splits halve by count (bounds the depth for any input).
const MAX_SAH_DEPTH: u32 = 48;
/// Subtrees bigger than this are built with `rayon::join`.
const PAR_THRESHOLD: usize = 8192;
/// Cost of a node visit relative to a triangle test (SAH).
const C_TRAV: f32 = 1.0;

const PAD_REL: f32 = 1e-6;
const PAD_ABS: f32 = 1e-6;

#[derive(Clone, Copy, Debug)]
pub(super) struct Aabb {
    pub(super) lo: Vec3A,
    pub(super) hi: Vec3A,
}

impl Aabb {
    pub(super) const EMPTY: Aabb = Aabb { lo: Vec3A::splat(f32::INFINITY), hi: Vec3A::splat(f32::NEG_INFINITY) };

    #[inline(always)]
    pub(super) fn grow(&mut self, lo: Vec3A, hi: Vec3A) {
        self.lo = self.lo.min(lo);
        self.hi = self.hi.max(hi);
    }

    #[inline(always)]
    pub(super) fn union(self, o: Aabb) -> Aabb {
        Aabb { lo: self.lo.min(o.lo), hi: self.hi.max(o.hi) }
    }

    /// Half the surface area.
    #[inline(always)]
    pub(super) fn half_area(&self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// A primitive to build over: box corners; `lo.w` carries the id bits (never computed on).
#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct Prim {
    lo: Vec4,
    hi: Vec4,
}

impl Prim {
    fn new(lo: Vec3A, hi: Vec3A, id: u32) -> Prim {
        Prim { lo: lo.extend(f32::from_bits(id)), hi: hi.extend(0.0) }
    }
    #[inline(always)]
    fn id(&self) -> u32 {
        self.lo.w.to_bits()
    }
    #[inline(always)]
    fn lo3(&self) -> Vec3A {
        Vec3A::from_vec4(self.lo)
    }
    #[inline(always)]
    fn hi3(&self) -> Vec3A {
        Vec3A::from_vec4(self.hi)
    }
    /// Twice the box centre.
    #[inline(always)]
    fn c2(&self) -> Vec3A {
        self.lo3() + self.hi3()
    }
}

pub(super) fn pad_lo(v: Vec3A) -> [f32; 3] {
    (v - (v.abs() * PAD_REL + Vec3A::splat(PAD_ABS))).to_array()
}
pub(super) fn pad_hi(v: Vec3A) -> [f32; 3] {
    (v + (v.abs() * PAD_REL + Vec3A::splat(PAD_ABS))).to_array()
}

fn leaf_node(b: &Aabb, a: u32, count: u32) -> Node {
    Node { lo: pad_lo(b.lo), a, hi: pad_hi(b.hi), b: count }
}
fn inner_node(b: &Aabb, child: u32) -> Node {
    Node { lo: pad_lo(b.lo), a: child, hi: pad_hi(b.hi), b: 0 }
}

/// Bounds and centroid bounds (of twice the centres) of a run of primitives.
#[derive(Clone, Copy, Debug)]
struct Extent {
    b: Aabb,
    cb: Aabb,
}

fn extent_of(prims: &[Prim]) -> Extent {
    let mut b = Aabb::EMPTY;
    let mut cb = Aabb::EMPTY;
    for p in prims {
        b.grow(p.lo3(), p.hi3());
        let c = p.c2();
        cb.grow(c, c);
    }
    Extent { b, cb }
}

/// Splits by count in the middle (for identical centroids or too deep trees).
fn split_half(prims: &[Prim]) -> (usize, Extent, Extent) {
    let mid = prims.len() / 2;
    (mid, extent_of(&prims[..mid]), extent_of(&prims[mid..]))
}

/// Chooses a split of `prims` (binned SAH) and partitions them in place, or None for a leaf.
fn split(prims: &mut [Prim], e: &Extent, depth: u32, max_leaf: usize) -> Option<(usize, Extent, Extent)> {
    let n = prims.len();
    if n <= 1 {
        return None;
    }
    let ext = e.cb.hi - e.cb.lo;
    let axis = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    let w = ext[axis];
    if !(w > 0.0) || depth >= MAX_SAH_DEPTH {
        return if n <= max_leaf { None } else { Some(split_half(prims)) };
    }
    let cmin = e.cb.lo[axis];
    let scale = BINS as f32 * (1.0 - 1e-6) / w;
    let bin_of = |p: &Prim| -> usize {
        let f = (p.c2()[axis] - cmin) * scale;
        (f as usize).min(BINS - 1) // saturating cast: NaN -> 0
    };
    // Two interleaved bin sets: neighbouring primitives often fall into the same bin, and
    // one set would chain every update through the same memory.
    let mut bins2 = [[Aabb::EMPTY; BINS]; 2];
    let mut counts2 = [[0u32; BINS]; 2];
    let mut pairs = prims.chunks_exact(2);
    for pp in &mut pairs {
        let (i, j) = (bin_of(&pp[0]), bin_of(&pp[1]));
        bins2[0][i].grow(pp[0].lo3(), pp[0].hi3());
        counts2[0][i] += 1;
        bins2[1][j].grow(pp[1].lo3(), pp[1].hi3());
        counts2[1][j] += 1;
    }
    for p in pairs.remainder() {
        let i = bin_of(p);
        bins2[0][i].grow(p.lo3(), p.hi3());
        counts2[0][i] += 1;
    }
    let bins: [Aabb; BINS] = std::array::from_fn(|k| bins2[0][k].union(bins2[1][k]));
    let counts: [u32; BINS] = std::array::from_fn(|k| counts2[0][k] + counts2[1][k]);
    // Sweep from the right: area and count of bins i+1.. for a split after bin i.
    let mut right_area = [0f32; BINS];
    let mut acc = Aabb::EMPTY;
    let mut cnt = 0u32;
    for i in (1..BINS).rev() {
        acc = acc.union(bins[i]);
        cnt += counts[i];
        right_area[i - 1] = if cnt > 0 { acc.half_area() * cnt as f32 } else { 0.0 };
    }
    let mut best = f32::INFINITY;
    let mut best_i = usize::MAX;
    let mut acc = Aabb::EMPTY;
    let mut cnt = 0u32;
    for i in 0..BINS - 1 {
        acc = acc.union(bins[i]);
        cnt += counts[i];
        if cnt == 0 || cnt as usize == n {
            continue;
        }
        let cost = acc.half_area() * cnt as f32 + right_area[i];
        if cost < best {
            best = cost;
            best_i = i;
        }
    }
    if best_i == usize::MAX {
        return if n <= max_leaf { None } else { Some(split_half(prims)) };
    }
    if n <= max_leaf {
        let area = e.b.half_area();
        let split_cost = C_TRAV + best / area;
        if !(split_cost < n as f32) {
            return None;
        }
    }
    // Partition (left: bin <= best_i), collecting both sides' extents.
    let mut l = Extent { b: Aabb::EMPTY, cb: Aabb::EMPTY };
    let mut r = l;
    let mut i = 0;
    let mut j = n;
    while i < j {
        let p = prims[i];
        let c = p.c2();
        if bin_of(&p) <= best_i {
            l.b.grow(p.lo3(), p.hi3());
            l.cb.grow(c, c);
            i += 1;
        } else {
            r.b.grow(p.lo3(), p.hi3());
            r.cb.grow(c, c);
            j -= 1;
            prims.swap(i, j);
        }
    }
    if i == 0 || i == n {
        return Some(split_half(prims));
    }
    Some((i, l, r))
}

/// Builds the subtree of `prims` into `nodes[idx]` and appended nodes (absolute indices).
fn build_seq(
    nodes: &mut Vec<Node>,
    idx: usize,
    prims: &mut [Prim],
    slot: u32,
    e: &Extent,
    depth: u32,
    leaf_flags: u32,
    max_leaf: usize,
) {
    match split(prims, e, depth, max_leaf) {
        None => nodes[idx] = leaf_node(&e.b, slot, prims.len() as u32 | leaf_flags),
        Some((mid, le, re)) => {
            let c = nodes.len();
            nodes.push(Node::default());
            nodes.push(Node::default());
            nodes[idx] = inner_node(&e.b, c as u32);
            let (lp, rp) = prims.split_at_mut(mid);
            build_seq(nodes, c, lp, slot, &le, depth + 1, leaf_flags, max_leaf);
            build_seq(nodes, c + 1, rp, slot + mid as u32, &re, depth + 1, leaf_flags, max_leaf);
        }
    }
}

/// Builds the subtree of `prims`; the returned array has the subtree root at 0 and local
/// child indices. Big subtrees are split with `rayon::join`.
fn build_par(prims: &mut [Prim], slot: u32, e: &Extent, depth: u32, leaf_flags: u32, max_leaf: usize) -> Vec<Node> {
    if prims.len() < PAR_THRESHOLD {
        let mut nodes = Vec::with_capacity(prims.len() / 2 + 1);
        nodes.push(Node::default());
        build_seq(&mut nodes, 0, prims, slot, e, depth, leaf_flags, max_leaf);
        return nodes;
    }
    match split(prims, e, depth, max_leaf) {
        None => vec![leaf_node(&e.b, slot, prims.len() as u32 | leaf_flags)],
        Some((mid, le, re)) => {
            let (lp, rp) = prims.split_at_mut(mid);
            let (lv, rv) = rayon::join(
                || build_par(lp, slot, &le, depth + 1, leaf_flags, max_leaf),
                || build_par(rp, slot + mid as u32, &re, depth + 1, leaf_flags, max_leaf),
            );
            join_subtrees(inner_node(&e.b, 1), &lv, &rv)
        }
    }
}

/// Builds a whole tree over `prims` (root at 0) or an empty array for no primitives.
fn build_tree(prims: &mut [Prim], slot: u32, leaf_flags: u32, max_leaf: usize) -> Vec<Node> {
    if prims.is_empty() {
        return Vec::new();
    }
    let e = extent_of(prims);
    build_par(prims, slot, &e, 0, leaf_flags, max_leaf)
}

// ---- Morton (LBVH) bottom level: O(n) after one sort, used for the per-frame meshes ----------

/// Leaf size of the Morton build.
const LBVH_LEAF: usize = 4;

/// Spreads the low 21 bits of `v` to every third bit.
fn spread3(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// Sorts `prims` along a 63-bit Morton curve of their centres (uniform scale over the
/// largest extent, ties by position in `prims`, which is id order: deterministic) and
/// returns the codes in the same order.
fn morton_sort(prims: &mut Vec<Prim>) -> Vec<u64> {
    let e = extent_of(prims);
    let ext = (e.cb.hi - e.cb.lo).max_element();
    let scale = if ext > 0.0 && ext.is_finite() { 2_097_151.0 / ext } else { 0.0 };
    let mut keyed: Vec<(u64, u32)> = prims
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let q = ((p.c2() - e.cb.lo) * scale).clamp(Vec3A::ZERO, Vec3A::splat(2_097_151.0));
            let code = spread3(q.x as u64) << 2 | spread3(q.y as u64) << 1 | spread3(q.z as u64);
            (code, k as u32)
        })
        .collect();
    // `prims` come in id order, so (code, k) orders ties by id.
    keyed.sort_unstable();
    *prims = keyed.iter().map(|&(_, k)| prims[k as usize]).collect();
    keyed.into_iter().map(|(c, _)| c).collect()
}

/// Split of a Morton-sorted run: at the highest differing bit, or in half for equal codes.
fn morton_split(codes: &[u64]) -> usize {
    let (first, last) = (codes[0], codes[codes.len() - 1]);
    if first == last {
        return codes.len() / 2;
    }
    let bit = 1u64 << (63 - (first ^ last).leading_zeros());
    codes.partition_point(|c| c & bit == 0)
}

/// Builds the Morton subtree into `nodes[idx]` (absolute indices); returns its bounds.
fn lbvh_seq(nodes: &mut Vec<Node>, idx: usize, prims: &[Prim], codes: &[u64], slot: u32, flags: u32) -> Aabb {
    if prims.len() <= LBVH_LEAF {
        let b = extent_of(prims).b;
        nodes[idx] = leaf_node(&b, slot, prims.len() as u32 | flags);
        return b;
    }
    let mid = morton_split(codes);
    let c = nodes.len();
    nodes.push(Node::default());
    nodes.push(Node::default());
    let lb = lbvh_seq(nodes, c, &prims[..mid], &codes[..mid], slot, flags);
    let rb = lbvh_seq(nodes, c + 1, &prims[mid..], &codes[mid..], slot + mid as u32, flags);
    let b = lb.union(rb);
    nodes[idx] = inner_node(&b, c as u32);
    b
}

/// Parallel Morton build (root at 0, local indices; same layout rules as `build_par`).
fn lbvh_par(prims: &[Prim], codes: &[u64], slot: u32, flags: u32) -> (Vec<Node>, Aabb) {
    if prims.len() < PAR_THRESHOLD {
        let mut nodes = Vec::with_capacity(prims.len() / 2 + 1);
        nodes.push(Node::default());
        let b = lbvh_seq(&mut nodes, 0, prims, codes, slot, flags);
        return (nodes, b);
    }
    let mid = morton_split(codes);
    let ((lv, lb), (rv, rb)) = rayon::join(
        || lbvh_par(&prims[..mid], &codes[..mid], slot, flags),
        || lbvh_par(&prims[mid..], &codes[mid..], slot + mid as u32, flags),
    );
    let b = lb.union(rb);
    (join_subtrees(inner_node(&b, 1), &lv, &rv), b)
}

/// `[root, left root, right root, left rest.., right rest..]` with child indices fixed.
fn join_subtrees(root: Node, lv: &[Node], rv: &[Node]) -> Vec<Node> {
    let mut out = Vec::with_capacity(1 + lv.len() + rv.len());
    out.push(root);
    let fix = |n: &Node, off: u32| -> Node {
        let mut n = *n;
        if n.b == 0 {
            n.a += off; // local index k >= 1 of a side array
        }
        n
    };
    let lo = 2u32;
    let ro = lv.len() as u32 + 1;
    out.push(fix(&lv[0], lo));
    out.push(fix(&rv[0], ro));
    out.extend(lv[1..].iter().map(|n| fix(n, lo)));
    out.extend(rv[1..].iter().map(|n| fix(n, ro)));
    out
}

// ---- Per-mesh bottom-level trees (their refit is in `refit.rs`) -----------------------------

/// One mesh's bottom-level tree: nodes with local indices (root at 0; leaf slots counted
/// from 0 within the mesh) and the local triangle of each slot. Its layout depends only on
/// the triangle count (the boxes are recomputed from the vertices on refit), so it can be
/// reused for any later pose of a mesh with the same index buffer.
#[derive(Clone, Debug, Default)]
pub(super) struct Blas {
    pub(super) nodes: Vec<Node>,
    /// Local triangle index (0..triangle_count) per slot.
    order: Vec<u32>,
    /// Unpadded boxes per node (refit scratch).
    pub(super) boxes: Vec<Aabb>,
    /// Sum of the node half areas right after the build (quality reference for refits).
    pub(super) built_area: f64,
}

impl Blas {
    /// Builds the tree of mesh `k` of `geom` from its current vertices (deterministic).
    pub(super) fn build(geom: &FrameGeometry, k: usize) -> Blas {
        let m = &geom.meshes[k];
        let first = m.first_triangle as usize;
        let tri_idx = &geom.indices[3 * first..3 * (first + m.triangle_count as usize)];
        let pos = &geom.positions;
        let mut prims: Vec<Prim> = tri_idx
            .chunks_exact(3)
            .enumerate()
            .map(|(j, i)| {
                let a = Vec3A::from(pos[i[0] as usize]);
                let b = Vec3A::from(pos[i[1] as usize]);
                let c = Vec3A::from(pos[i[2] as usize]);
                Prim::new(a.min(b).min(c), a.max(b).max(c), j as u32)
            })
            .collect();
        let flags = if m.double_sided { 0 } else { CULL_BIT };
        let nodes = if BOTTOM_SAH {
            build_tree(&mut prims, 0, flags, MAX_LEAF)
        } else {
            let codes = morton_sort(&mut prims);
            lbvh_par(&prims, &codes, 0, flags).0
        };
        let order = prims.iter().map(|p| p.id()).collect();
        Blas { nodes, order, boxes: Vec::new(), built_area: 0.0 }
    }

    /// Writes the current vertices and global triangle indices of mesh `k` in slot order.
    pub(super) fn fill_slots(&self, geom: &FrameGeometry, k: usize, verts: &mut [[f32; 9]], ids: &mut [u32]) {
        let m = &geom.meshes[k];
        let first = m.first_triangle as usize;
        let tri_idx = &geom.indices[3 * first..3 * (first + m.triangle_count as usize)];
        let pos = &geom.positions;
        for ((&j, vs), id) in self.order.iter().zip(verts.iter_mut()).zip(ids.iter_mut()) {
            *id = first as u32 + j;
            let t = &tri_idx[3 * j as usize..3 * j as usize + 3];
            let [a, b, c] = [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]];
            *vs = [a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]];
        }
    }
}

/// The per-slot arrays of `geom` (vertices, triangle ids), reusing the given allocations;
/// their contents are stale (every slot is overwritten by `Blas::fill_slots`).
pub(super) fn slot_arrays(geom: &FrameGeometry, mut verts: Vec<[f32; 9]>, mut ids: Vec<u32>) -> (Vec<[f32; 9]>, Vec<u32>) {
    let total: usize = geom.meshes.iter().map(|m| m.triangle_count as usize).sum();
    verts.truncate(total);
    verts.resize(total, [0f32; 9]);
    ids.truncate(total);
    ids.resize(total, 0);
    (verts, ids)
}

/// The slot arrays split per mesh: `(mesh, its verts, its ids)`.
pub(super) fn slot_jobs<'a>(
    geom: &FrameGeometry,
    verts: &'a mut [[f32; 9]],
    ids: &'a mut [u32],
) -> Vec<(usize, &'a mut [[f32; 9]], &'a mut [u32])> {
    let mut jobs = Vec::with_capacity(geom.meshes.len());
    let mut vrest = verts;
    let mut irest = ids;
    for (k, m) in geom.meshes.iter().enumerate() {
        let n = m.triangle_count as usize;
        let (v, vr) = vrest.split_at_mut(n);
        let (i, ir) = irest.split_at_mut(n);
        vrest = vr;
        irest = ir;
        jobs.push((k, v, i));
    }
    jobs
}

/// One mesh of the BVH.
#[derive(Clone, Copy, Debug)]
pub(super) struct MeshEntry {
    /// Index into `FrameGeometry::meshes`.
    mesh: u32,
    /// Root node in `Bvh::nodes`.
    pub(super) root: u32,
    /// Bounds (the padded root box).
    bounds: Aabb,
}

/// Top-level BVH over (a subset of) the meshes.
#[derive(Clone, Debug, Default)]
pub(super) struct Tlas {
    pub(super) nodes: Vec<Node>,
}

/// A two-level BVH over the triangles of one `FrameGeometry` (built per frame).
/// It keeps its own copy of the triangles (f32, in leaf order), so casting does not touch the
/// geometry; pass the same geometry to `cast` (checked by counts).
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    /// All bottom-level nodes, one tree per non-empty mesh.
    pub(super) nodes: Vec<Node>,
    /// Triangle vertices in leaf-slot order.
    pub(super) verts: Vec<[f32; 9]>,
    /// Global triangle index per slot.
    pub(super) ids: Vec<u32>,
    pub(super) meshes: Vec<MeshEntry>,
    pub(super) tlas: Tlas,
    triangle_count: u32,
    mesh_count: usize,
}

impl Bvh {
    /// Builds the BVH of `geom` (parallel with rayon over meshes and big subtrees).
    /// Triangles outside every mesh range are ignored (as by the rasterizer).
    pub fn build(geom: &FrameGeometry) -> Bvh {
        let (mut verts, mut ids) = slot_arrays(geom, Vec::new(), Vec::new());
        let jobs = slot_jobs(geom, &mut verts, &mut ids);
        let built: Vec<(usize, Blas)> = jobs
            .into_par_iter()
            .filter(|(_, v, _)| !v.is_empty())
            .map(|(k, v, i)| {
                let blas = Blas::build(geom, k);
                blas.fill_slots(geom, k, v, i);
                (k, blas)
            })
            .collect();
        let trees: Vec<(usize, &[Node])> = built.iter().map(|(k, b)| (*k, &b.nodes[..])).collect();
        Bvh::assemble(geom, &trees, verts, ids, Vec::new())
    }

    /// Concatenates the bottom-level trees (local node indices, leaf slots local to the mesh)
    /// into one node array and builds the top level.
    /// `nodes`: an allocation to reuse (its contents are overwritten).
    pub(super) fn assemble(
        geom: &FrameGeometry,
        trees: &[(usize, &[Node])],
        verts: Vec<[f32; 9]>,
        ids: Vec<u32>,
        mut nodes: Vec<Node>,
    ) -> Bvh {
        let mut slot_of = Vec::with_capacity(geom.meshes.len());
        let mut slot = 0u32;
        for m in &geom.meshes {
            slot_of.push(slot);
            slot += m.triangle_count;
        }
        let node_total: usize = trees.iter().map(|(_, n)| n.len()).sum();
        nodes.truncate(node_total);
        nodes.resize(node_total, Node::default());
        let mut meshes = Vec::with_capacity(trees.len());
        let mut jobs = Vec::with_capacity(trees.len());
        {
            let mut rest: &mut [Node] = &mut nodes;
            let mut base = 0u32;
            for (k, sub) in trees {
                let (out, r) = rest.split_at_mut(sub.len());
                rest = r;
                let root = &sub[0];
                // The root's (padded) box; padding it again in the top level is only conservative.
                let bounds = Aabb { lo: Vec3A::from(root.lo), hi: Vec3A::from(root.hi) };
                meshes.push(MeshEntry { mesh: *k as u32, root: base, bounds });
                jobs.push((out, *sub, base, slot_of[*k]));
                base += sub.len() as u32;
            }
        }
        jobs.into_par_iter().with_min_len(1).for_each(|(out, sub, base, slot)| {
            for (o, n) in out.iter_mut().zip(sub) {
                *o = *n;
                if n.b == 0 {
                    o.a += base;
                } else {
                    o.a += slot;
                }
            }
        });
        let mut bvh = Bvh {
            nodes,
            verts,
            ids,
            meshes,
            tlas: Tlas::default(),
            triangle_count: geom.triangle_count(),
            mesh_count: geom.meshes.len(),
        };
        bvh.tlas = bvh.build_tlas(|_| true);
        bvh
    }

    pub(super) fn build_tlas(&self, keep: impl Fn(u32) -> bool) -> Tlas {
        let mut prims: Vec<Prim> = self
            .meshes
            .iter()
            .enumerate()
            .filter(|(_, m)| keep(m.mesh))
            .map(|(e, m)| Prim::new(m.bounds.lo, m.bounds.hi, e as u32))
            .collect();
        let mut nodes = build_tree(&mut prims, 0, 0, 1);
        // Top-level leaves hold one mesh: point them at the entry (slot order = prims order).
        for n in nodes.iter_mut() {
            if n.b != 0 {
                n.a = prims[n.a as usize].id();
                n.b = 1;
            }
        }
        Tlas { nodes }
    }

    /// Number of triangles in the BVH (those of all meshes).
    pub fn triangle_count(&self) -> usize {
        self.ids.len()
    }

    /// Number of bottom-level nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    pub(super) fn check(&self, geom: &FrameGeometry) {
        assert!(
            self.triangle_count == geom.triangle_count() && self.mesh_count == geom.meshes.len(),
            "raycast: the BVH was built for another geometry"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::raycast::cast;
    use crate::backend::raycast::test_support::{octasphere, same, soup};
    use glam::DVec3;

    /// Same results (and the same BVH) with 1 and 2 rayon threads.
    #[test]
    fn deterministic_across_thread_counts() {
        let (g, dirs) = soup(30, 3000);
        // A big mesh too, so that the parallel subtree build runs.
        let (p, i) = octasphere(40, DVec3::new(3.0, 2.0, 1.0), DVec3::new(10.0, -3.0, 0.0));
        let mut g = g;
        g.push_mesh(&p, &i, 9, false);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let bvh = Bvh::build(&g);
                (cast(&g, &bvh, &dirs, 1e9), bvh.node_count())
            })
        };
        let (a, na) = run(1);
        let (b, nb) = run(2);
        assert_eq!(na, nb);
        same(&a, &b).unwrap();
        let (c, _) = run(3);
        same(&a, &c).unwrap();
    }
}
