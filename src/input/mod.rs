//! Stage 2: recorded inputs. Backgrounds as per-frame point clouds from the formats people
//! have (KITTI `.bin`, PCD, raw Velodyne `.pcap`), sensor poses (KITTI `poses.txt`, TUM),
//! the projection of a recorded frame onto the target sensor's beam grid, and recorded
//! pedestrian tracks ([`tracks`]: ETH/UCY, ATC, CSV).
//!
//! Every reader returns [`Scan`]s in the *recording* sensor's frame (x forward, y left, z up,
//! metres). Bad input is an [`crate::Error::input`] naming the file and the line or record.

pub mod kitti;
pub mod pcap;
pub mod pcd;
pub mod poses;
pub mod project;
pub mod recording;
pub mod tracks;

pub use recording::Recording;

/// One recorded frame (one rotation) in the recording sensor's frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scan {
    /// Returns, metres, sensor frame. Readers drop non-finite and all-zero points.
    pub points: Vec<[f32; 3]>,
    /// Laser ring per point, when the source has one (pcap, PCD with a `ring` field).
    pub ring: Option<Vec<u16>>,
    /// Elevation of each ring, degrees, indexed by ring, when known (pcap: the sensor's
    /// vertical angle table). A PCD `ring` field comes without one.
    pub ring_elevation_deg: Option<Vec<f64>>,
    /// Capture time of the frame, seconds (pcap: first packet of the rotation), when known.
    pub time_s: Option<f64>,
}
