//! Checks of a glTF document's structure before the `gltf` crate's readers see it, shared by
//! the human loader and the environment loader (`crate::scene::Environment::load`).
//!
//! The readers trust the file: an index accessor of floats reaches `unreachable!`, an element
//! past the end of its buffer view silently ends the data (a missing attribute), a sparse
//! accessor without a view yields `count` zeros whatever `count` is. So every accessor is held
//! against what its reader assumes (component type, element type, normalization) and against
//! its buffer view and buffer before it is read, and the node hierarchy against the strict
//! trees the specification requires before it is walked.

use crate::error::{Error, Result};
use gltf::accessor::{DataType, Dimensions};
use std::path::Path;

/// Deepest node hierarchy accepted (skeletons and scenes are a few dozen levels deep).
pub const MAX_NODE_DEPTH: usize = 512;

/// What a reader of the `gltf` crate assumes of an accessor.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    /// Accepted component types.
    pub types: &'static [DataType],
    pub dims: Dimensions,
    /// Integer components must be normalized (weights, rotations) or must not be (indices,
    /// joints). Float components are never normalized.
    pub normalized: bool,
}

/// Triangle indices.
pub(crate) const INDICES: Layout =
    Layout { types: &[DataType::U8, DataType::U16, DataType::U32], dims: Dimensions::Scalar, normalized: false };
/// Vertex positions.
pub(crate) const POSITIONS: Layout = Layout { types: &[DataType::F32], dims: Dimensions::Vec3, normalized: false };
/// Skin joint indices, four per vertex.
pub(crate) const JOINTS: Layout = Layout { types: &[DataType::U8, DataType::U16], dims: Dimensions::Vec4, normalized: false };
/// Skin weights, four per vertex.
pub(crate) const WEIGHTS: Layout =
    Layout { types: &[DataType::F32, DataType::U8, DataType::U16], dims: Dimensions::Vec4, normalized: true };
/// A skin's inverse bind matrices.
pub(crate) const MATRICES: Layout = Layout { types: &[DataType::F32], dims: Dimensions::Mat4, normalized: false };
/// An animation sampler's input times.
pub(crate) const TIMES: Layout = Layout { types: &[DataType::F32], dims: Dimensions::Scalar, normalized: false };
/// Translation and scale keyframes.
pub(crate) const VEC3_KEYS: Layout = Layout { types: &[DataType::F32], dims: Dimensions::Vec3, normalized: false };
/// Rotation keyframes (quaternions).
pub(crate) const ROTATION_KEYS: Layout = Layout {
    types: &[DataType::F32, DataType::I8, DataType::U8, DataType::I16, DataType::U16],
    dims: Dimensions::Vec4,
    normalized: true,
};

/// Parses a glTF or GLB file's container. A GLB whose header declares a length shorter than
/// the header itself is refused here: the `gltf` crate subtracts the header size from it
/// unchecked (an overflow panic where overflow checks are on).
pub(crate) fn parse(bytes: &[u8]) -> Result<gltf::Gltf, String> {
    if bytes.len() >= 12 && &bytes[..4] == b"glTF" {
        let length = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
        if length < 12 {
            return Err(format!("GLB header declares {length} bytes, less than the 12-byte header itself"));
        }
    }
    let json = if bytes.starts_with(b"glTF") {
        gltf::Glb::from_slice(bytes).map_err(|e| format!("not a valid GLB: {e}"))?.json
    } else {
        std::borrow::Cow::Borrowed(bytes)
    };
    let root = gltf::json::Root::from_slice(&json).map_err(|e| format!("not a valid glTF: {e}"))?;
    references(&root)?;
    gltf::Gltf::from_slice(bytes).map_err(|e| format!("not a valid glTF: {e}"))
}

/// The references the `gltf` crate follows without checking them (its validator indexes a
/// primitive's POSITION accessor directly, and animation channel targets are not validated,
/// then unwrapped by their readers): each must name an element that exists.
fn references(root: &gltf::json::Root) -> Result<(), String> {
    use gltf::json::validation::Checked;
    let accessors = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let targets = prim.targets.iter().flatten().flat_map(|t| [t.positions, t.normals, t.tangents]).flatten();
            for a in prim.attributes.values().copied().chain(prim.indices).chain(targets) {
                if a.value() >= accessors {
                    return Err(format!("meshes[{m}].primitives[{p}] names accessor {} of {accessors}", a.value()));
                }
            }
        }
    }
    for (a, anim) in root.animations.iter().enumerate() {
        for (c, ch) in anim.channels.iter().enumerate() {
            if ch.target.node.value() >= root.nodes.len() {
                return Err(format!("animations[{a}].channels[{c}] targets node {} of {}", ch.target.node.value(), root.nodes.len()));
            }
            if !matches!(ch.target.path, Checked::Valid(_)) {
                return Err(format!("animations[{a}].channels[{c}] targets an unknown property"));
            }
        }
        for (k, smp) in anim.samplers.iter().enumerate() {
            if smp.input.value() >= accessors || smp.output.value() >= accessors {
                return Err(format!("animations[{a}].samplers[{k}] names an accessor beyond the {accessors} there are"));
            }
        }
    }
    Ok(())
}

/// Checks accessor `acc` (called `what` in errors, e.g. "JOINTS_0 of mesh 0 primitive 1")
/// of the file `path`: its layout where `layout` is given, and in every case that it is
/// dense (not sparse), holds at least one element, and that every element lies inside its
/// buffer view and the view inside its buffer (`offset + stride * (count - 1) + size <=
/// length`), so its count is bounded by the file's size. Returns the count.
pub(crate) fn accessor(
    path: &Path,
    what: &str,
    acc: &gltf::Accessor,
    layout: Option<&Layout>,
    buffers: &[gltf::buffer::Data],
) -> Result<usize> {
    let bad = |m: String| Err(Error::input(path.display(), format!("accessor {} ({what}) {m}", acc.index())));
    if let Some(l) = layout {
        let (ty, dims) = (acc.data_type(), acc.dimensions());
        if !l.types.contains(&ty) || dims != l.dims {
            let names: Vec<String> = l.types.iter().map(|t| format!("{t:?}")).collect();
            return bad(format!("holds {ty:?} {dims:?}; it must be {} {:?}", names.join(" or "), l.dims));
        }
        if ty != DataType::F32 && acc.normalized() != l.normalized {
            let must = if l.normalized { "must" } else { "must not" };
            return bad(format!("{must} be normalized"));
        }
    }
    if acc.sparse().is_some() {
        return bad("is sparse; sparse accessors are not supported".into());
    }
    let Some(view) = acc.view() else {
        return bad("has no buffer view".into());
    };
    let count = acc.count();
    if count == 0 {
        return bad("is empty (count 0)".into());
    }
    let size = acc.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return bad(format!("has elements of {size} bytes but buffer view {} a stride of {stride}", view.index()));
    }
    let buffer_len = buffers.get(view.buffer().index()).map_or(0, |b| b.len());
    if view.offset().checked_add(view.length()).map_or(true, |end| end > buffer_len) {
        return bad(format!(
            "reads buffer view {}, whose {} bytes at offset {} do not fit in buffer {} of {buffer_len} bytes",
            view.index(),
            view.length(),
            view.offset(),
            view.buffer().index()
        ));
    }
    let end = stride
        .checked_mul(count - 1)
        .and_then(|s| s.checked_add(size))
        .and_then(|s| s.checked_add(acc.offset()));
    if end.map_or(true, |end| end > view.length()) {
        return bad(format!(
            "has {count} elements of {size} bytes at offset {} (stride {stride}), past the end of buffer view {} of {} bytes",
            acc.offset(),
            view.index(),
            view.length()
        ));
    }
    Ok(count)
}

/// Checks the accessors of primitive `prim` of `mesh` before it is read: POSITION and the
/// indices as their readers assume them, JOINTS_0 and WEIGHTS_0 too where `skinned`, and that
/// every attribute fits its buffer with as many elements as POSITION. Returns its vertex and
/// index counts, or `None` for a primitive that is not read (not triangles, or without
/// POSITION).
pub(crate) fn primitive(
    path: &Path,
    mesh: &gltf::Mesh,
    prim: &gltf::Primitive,
    buffers: &[gltf::buffer::Data],
    skinned: bool,
) -> Result<Option<(usize, usize)>> {
    use gltf::Semantic;
    if prim.mode() != gltf::mesh::Mode::Triangles {
        return Ok(None);
    }
    let Some(position) = prim.get(&Semantic::Positions) else { return Ok(None) };
    let at = |what: &str| format!("{what} of mesh {} primitive {}", mesh.index(), prim.index());
    let n = accessor(path, &at("POSITION"), &position, Some(&POSITIONS), buffers)?;
    for (semantic, acc) in prim.attributes() {
        let layout = match semantic {
            Semantic::Joints(0) if skinned => Some(&JOINTS),
            Semantic::Weights(0) if skinned => Some(&WEIGHTS),
            _ => None,
        };
        let what = at(&semantic.to_string());
        let count = accessor(path, &what, &acc, layout, buffers)?;
        if count != n {
            return Err(Error::input(path.display(), format!("{what} has {count} elements but POSITION has {n}")));
        }
    }
    if skinned {
        for s in [Semantic::Joints(0), Semantic::Weights(0)] {
            if prim.get(&s).is_none() {
                return Err(Error::input(path.display(), format!("{} is missing; the model has a skin", at(&s.to_string()))));
            }
        }
    }
    let corners = match prim.indices() {
        Some(idx) => accessor(path, &at("indices"), &idx, Some(&INDICES), buffers)?,
        None => n,
    };
    Ok(Some((n, corners)))
}

/// The parent of every node of `doc` (in the file `path`), after checking that the nodes
/// form strict trees: no node is the child of two nodes (or twice of one), none is its own
/// ancestor, and none lies deeper than [`MAX_NODE_DEPTH`].
pub(crate) fn node_parents(path: &Path, doc: &gltf::Document) -> Result<Vec<Option<usize>>> {
    let bad = |m: String| Err(Error::input(path.display(), m));
    let mut parents: Vec<Option<usize>> = vec![None; doc.nodes().len()];
    for n in doc.nodes() {
        for c in n.children() {
            if let Some(p) = parents[c.index()] {
                return bad(format!("node {} is a child of both node {p} and node {}; nodes must form trees", c.index(), n.index()));
            }
            parents[c.index()] = Some(n.index());
        }
    }
    // Depth of each node, found by walking up from it until a node of known depth or a root;
    // a node met again on the same walk is its own ancestor.
    const UNKNOWN: usize = usize::MAX;
    const ON_WALK: usize = usize::MAX - 1;
    let mut depth = vec![UNKNOWN; parents.len()];
    let mut walk = Vec::new();
    for start in 0..parents.len() {
        let mut k = start;
        let mut base = loop {
            match depth[k] {
                UNKNOWN => {}
                ON_WALK => return bad(format!("node {k} is its own ancestor: the node hierarchy has a cycle")),
                d => break d + 1,
            }
            depth[k] = ON_WALK;
            walk.push(k);
            match parents[k] {
                Some(p) => k = p,
                None => break 0,
            }
        };
        while let Some(k) = walk.pop() {
            if base > MAX_NODE_DEPTH {
                return bad(format!("node {k} lies {base} levels deep, more than the supported {MAX_NODE_DEPTH}"));
            }
            depth[k] = base;
            base += 1;
        }
    }
    Ok(parents)
}

/// Checks that every root node of `scene` is a root of the hierarchy (no parent), listed once.
pub(crate) fn scene_roots(path: &Path, scene: &gltf::Scene, parents: &[Option<usize>]) -> Result<()> {
    let mut listed = vec![false; parents.len()];
    for n in scene.nodes() {
        let i = n.index();
        if let Some(p) = parents[i] {
            return Err(Error::input(path.display(), format!("node {i} is a root of scene {} and a child of node {p}", scene.index())));
        }
        if std::mem::replace(&mut listed[i], true) {
            return Err(Error::input(path.display(), format!("node {i} is listed twice as a root of scene {}", scene.index())));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_the_gltf_crate_follows_unchecked_are_refused() {
        let base = r#""asset":{"version":"2.0"},"accessors":[{"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}],"nodes":[{}]"#;
        let mesh = format!(r#"{{{base},"meshes":[{{"primitives":[{{"attributes":{{"POSITION":2}}}}]}}]}}"#);
        assert!(parse(mesh.as_bytes()).unwrap_err().contains("names accessor 2 of 1"));
        let anim = |target: &str| format!(r#"{{{base},"animations":[{{"samplers":[{{"input":0,"output":0}}],"channels":[{{"sampler":0,"target":{target}}}]}}]}}"#);
        assert!(parse(anim(r#"{"node":5,"path":"rotation"}"#).as_bytes()).unwrap_err().contains("targets node 5 of 1"));
        assert!(parse(anim(r#"{"node":0,"path":"spin"}"#).as_bytes()).unwrap_err().contains("unknown property"));
        let fine = gltf::json::Root::from_slice(anim(r#"{"node":0,"path":"rotation"}"#).as_bytes()).unwrap();
        assert_eq!(references(&fine), Ok(()));
    }

    #[test]
    fn a_glb_shorter_than_its_header_is_refused_not_a_panic() {
        let mut glb = b"glTF".to_vec();
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&4u32.to_le_bytes());
        glb.extend_from_slice(&[0; 8]);
        assert!(parse(&glb).unwrap_err().contains("less than the 12-byte header"));
    }
}
