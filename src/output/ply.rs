//! Posed human triangles of one frame in the sensor frame as binary little-endian PLY, so
//! anyone can check pedscan's ranges with an outside ray-caster and the beam table of the HDF5
//! (`/sensor/elevation_deg`, `/sensor/azimuth_deg`). Faces carry an `instance` property that
//! matches `/instance`.

use crate::error::{Error, Result};
use crate::geometry::FrameGeometry;
use std::io::Write;
use std::path::Path;

/// Writes the meshes of `geom` with `instance > 0` to `path` (temporary name, then rename).
pub fn write_humans_ply(path: &Path, geom: &FrameGeometry) -> Result<()> {
    let meshes: Vec<_> = geom.meshes.iter().filter(|m| m.instance > 0).collect();
    let faces: usize = meshes.iter().map(|m| m.triangle_count as usize).sum();
    // Vertices: only those the kept triangles use, in first-use order.
    let mut remap = vec![u32::MAX; geom.positions.len()];
    let mut verts: Vec<[f32; 3]> = Vec::new();
    let mut tris: Vec<([u32; 3], u32)> = Vec::with_capacity(faces);
    for m in &meshes {
        for t in m.first_triangle..m.first_triangle + m.triangle_count {
            let mut f = [0u32; 3];
            for (k, slot) in f.iter_mut().enumerate() {
                let i = geom.indices[3 * t as usize + k] as usize;
                if remap[i] == u32::MAX {
                    remap[i] = verts.len() as u32;
                    verts.push(geom.positions[i]);
                }
                *slot = remap[i];
            }
            tris.push((f, m.instance));
        }
    }
    let mut buf = Vec::with_capacity(200 + verts.len() * 12 + tris.len() * 17);
    write!(
        buf,
        "ply\nformat binary_little_endian 1.0\ncomment pedscan {} posed humans, sensor frame (x forward, y left, z up), metres\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {}\nproperty list uchar int vertex_indices\nproperty int instance\nend_header\n",
        crate::version(),
        verts.len(),
        tris.len()
    )
    .expect("write to Vec");
    for v in &verts {
        for c in v {
            buf.extend_from_slice(&c.to_le_bytes());
        }
    }
    for (f, inst) in &tris {
        buf.push(3);
        for i in f {
            buf.extend_from_slice(&(*i as i32).to_le_bytes());
        }
        buf.extend_from_slice(&(*inst as i32).to_le_bytes());
    }
    let tmp = path.with_extension("ply.tmp");
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    std::fs::write(&tmp, &buf).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ply_holds_only_humans_with_their_instance() {
        let mut g = FrameGeometry::default();
        let tri = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 1.0]];
        g.push_mesh(&tri, &[0, 1, 2], 0, true);
        g.push_mesh(&tri, &[0, 1, 2], 4, false);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.ply");
        write_humans_ply(&p, &g).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains("element vertex 3\n") && text.contains("element face 1\n"), "{text}");
        let body = &bytes[text.find("end_header\n").unwrap() + 11..];
        assert_eq!(body.len(), 3 * 12 + 1 + 12 + 4);
        assert_eq!(f32::from_le_bytes(body[0..4].try_into().unwrap()), 1.0);
        assert_eq!(i32::from_le_bytes(body[body.len() - 4..].try_into().unwrap()), 4);
        assert!(!dir.path().join("f.ply.tmp").exists());
    }
}
