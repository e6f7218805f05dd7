//! Sensor presets beyond the paper's HDL-32E: each sensor's beam elevations (row 0 highest),
//! columns, rate and range limits, with where each table comes from. The grid is the
//! sensor's *destaggered* image, as Ouster's SDK and the ROS drivers' organized clouds present
//! it: every row of a column at that column's azimuth. Per-laser azimuth offsets (VLP-32C
//! +-1.4 / +-4.2 deg, Ouster +-1.4 / +-4.25 deg, Pandar64 +-1.04 to +-5.21 deg, HDL-64E per
//! unit) are left out: on the destaggered grid they change only when a pixel's laser fired,
//! at most 1.45 ms from its column's time at 10 Hz (millimetres of motion; docs/sensor-model.md, Sensor
//! presets).

/// Velodyne HDL-64E S3: a unit's calibration (`64e_s3-xiesc.yaml`, ros-drivers/velodyne
/// `velodyne_pointcloud/params`), sorted; the datasheet's field of view is +2 to -24.9 deg.
pub const HDL64E_ELEVATION_DEG: [f64; 64] = [
    1.96, 1.562, 1.293, 0.895, 0.591, 0.204, -0.089, -0.452, -0.756, -1.143, -1.459, -1.81, -2.091,
    -2.488, -2.792, -3.119, -3.469, -3.819, -4.157, -4.53, -4.809, -5.135, -5.483, -5.889, -6.19,
    -6.56, -6.849, -7.23, -7.552, -7.943, -8.219, -8.563, -8.775, -9.3, -9.744, -10.176, -10.754,
    -11.295, -11.913, -12.294, -12.83, -13.163, -13.806, -14.291, -14.927, -15.385, -15.906,
    -16.274, -16.801, -17.368, -17.964, -18.429, -18.923, -19.247, -19.892, -20.429, -21.064,
    -21.491, -21.976, -22.358, -22.966, -23.549, -24.147, -24.555,
];

/// Velodyne VLP-32C (Ultra Puck): the user manual's laser table (63-9325 Rev C, Table 9-6;
/// ros-drivers/velodyne `VeloView-VLP-32C.yaml` holds the same), sorted.
pub const VLP32C_ELEVATION_DEG: [f64; 32] = [
    15.0, 10.333, 7.0, 4.667, 3.333, 2.333, 1.667, 1.333, 1.0, 0.667, 0.333, 0.0, -0.333, -0.667,
    -1.0, -1.333, -1.667, -2.0, -2.333, -2.667, -3.0, -3.333, -3.667, -4.0, -4.667, -5.333, -6.148,
    -7.254, -8.843, -11.31, -15.639, -25.0,
];

/// Ouster OS1-64 (gen 2, uniform beam spacing): a unit's `beam_altitude_angles` (OS-1-64-U02,
/// firmware 2.0.0; ouster-lidar/ouster-sdk `ouster_ros/metadata/os1_64.json`).
pub const OS1_64_ELEVATION_DEG: [f64; 64] = [
    21.02, 20.39, 19.76, 19.15, 18.5, 17.86, 17.21, 16.58, 15.91, 15.27, 14.6, 13.94, 13.26, 12.6,
    11.9, 11.24, 10.55, 9.87, 9.18, 8.48, 7.77, 7.09, 6.38, 5.69, 4.99, 4.3, 3.59, 2.9, 2.19, 1.48,
    0.77, 0.06, -0.65, -1.34, -2.06, -2.76, -3.46, -4.17, -4.85, -5.57, -6.27, -6.95, -7.66, -8.34,
    -9.04, -9.73, -10.42, -11.09, -11.76, -12.45, -13.12, -13.78, -14.45, -15.09, -15.76, -16.41,
    -17.06, -17.69, -18.32, -18.95, -19.57, -20.19, -20.8, -21.41,
];

/// Ouster OS1-128: the symmetric table of the SDK's test metadata (OS-1-128, firmware 2.0.0;
/// ouster-sdk `tests/metadata/2_0_0_os1-992008000494-128_col_win_legacy.json`), +-21.48 deg.
pub const OS1_128_ELEVATION_DEG: [f64; 128] = [
    21.476, 21.168, 20.858, 20.548, 20.236, 19.922, 19.608, 19.292, 18.975, 18.657, 18.337, 18.017,
    17.695, 17.373, 17.049, 16.724, 16.398, 16.072, 15.744, 15.414, 15.084, 14.754, 14.422, 14.088,
    13.754, 13.42, 13.084, 12.747, 12.409, 12.072, 11.733, 11.391, 11.05, 10.71, 10.367, 10.022,
    9.678, 9.335, 8.989, 8.641, 8.294, 7.948, 7.6, 7.249, 6.899, 6.551, 6.2, 5.847, 5.496, 5.145,
    4.793, 4.438, 4.084, 3.732, 3.377, 3.022, 2.667, 2.313, 1.957, 1.601, 1.245, 0.89, 0.534,
    0.178, -0.178, -0.534, -0.89, -1.245, -1.601, -1.957, -2.313, -2.667, -3.022, -3.377, -3.732,
    -4.084, -4.438, -4.793, -5.145, -5.496, -5.847, -6.2, -6.551, -6.899, -7.249, -7.6, -7.948,
    -8.294, -8.641, -8.989, -9.335, -9.678, -10.022, -10.367, -10.71, -11.05, -11.391, -11.733,
    -12.072, -12.409, -12.747, -13.084, -13.42, -13.754, -14.088, -14.422, -14.754, -15.084,
    -15.414, -15.744, -16.072, -16.398, -16.724, -17.049, -17.373, -17.695, -18.017, -18.337,
    -18.657, -18.975, -19.292, -19.608, -19.922, -20.236, -20.548, -20.858, -21.168, -21.476,
];

/// Hesai Pandar64: the SDK's built-in angle table (HesaiTechnology/HesaiLidar_General_SDK,
/// `pandarGeneral_internal.cc`, `pandarGeneral_elev_angle_map`), +14.88 to -24.90 deg.
pub const PANDAR64_ELEVATION_DEG: [f64; 64] = [
    14.882, 11.032, 8.059, 5.057, 3.04, 2.028, 1.86, 1.688, 1.522, 1.351, 1.184, 1.013, 0.846,
    0.675, 0.508, 0.337, 0.169, 0.0, -0.169, -0.337, -0.508, -0.675, -0.845, -1.013, -1.184,
    -1.351, -1.522, -1.688, -1.86, -2.028, -2.198, -2.365, -2.536, -2.7, -2.873, -3.04, -3.21,
    -3.375, -3.548, -3.712, -3.884, -4.05, -4.221, -4.385, -4.558, -4.72, -4.892, -5.057, -5.229,
    -5.391, -5.565, -5.726, -5.898, -6.061, -7.063, -8.059, -9.06, -9.885, -11.032, -12.006,
    -12.974, -13.93, -18.889, -24.897,
];

/// Ouster OS0-128: the datasheet's 90 deg field of view, +-45 deg, in 128 uniform rows (units
/// are calibrated each: give yours as its metadata JSON, `--sensor FILE.json`).
pub fn os0_128_elevation_deg() -> Vec<f64> {
    (0..128).map(|r| 45.0 - r as f64 * 90.0 / 127.0).collect()
}
