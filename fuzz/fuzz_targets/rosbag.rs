#![no_main]
//! ROS 2 bags: the input's first byte (mod 5) picks what the rest is. 0 and 4: an MCAP file,
//! read as a background is (the only PointCloud2 topic; poses from `/tf`, or with 4 from an
//! `/odom` Odometry topic), every cloud projected and its firings turned into column times.
//! 1, 2, 3: one CDR payload of a PointCloud2 (then its scan), a TFMessage or an Odometry.
use libfuzzer_sys::fuzz_target;
use pedscan::input::rosbag::{cdr, read_bag, to_scan, BagOptions};

fn scan_of(scan: &pedscan::input::Scan) {
    pedscan_fuzz::project(scan);
    if let (Some(firings), Some(t0)) = (&scan.firing_times, scan.time_s) {
        let relative: Vec<[f64; 2]> = firings.iter().map(|&[a, t]| [a, t - t0]).collect();
        if let Ok(times) = pedscan::input::sweep::boundary_times(&relative, 1024) {
            assert!(times.windows(2).all(|w| w[1] > w[0]), "column times increase strictly");
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    match mode % 5 {
        0 | 4 => {
            let path = pedscan_fuzz::input_file("bag.mcap", rest);
            let odometry = mode % 5 == 4;
            let opts = BagOptions { poses_topic: odometry.then(|| "/odom".to_string()), ..Default::default() };
            if let Ok(bag) = read_bag(&path, &opts, |s, _| {
                scan_of(s);
                Ok(s.points.len())
            }) {
                assert!(bag.times_s.windows(2).all(|w| w[1] > w[0]), "frame times increase strictly");
                assert_eq!(bag.frames.len(), bag.times_s.len());
                if let Some(p) = &bag.poses {
                    assert_eq!(p.len(), bag.frames.len());
                }
            }
        }
        1 => {
            if let Ok(c) = cdr::Cloud::decode(rest) {
                if let Ok(scan) = to_scan(&c, c.stamp_ns) {
                    scan_of(&scan);
                }
            }
        }
        2 => {
            let _ = cdr::decode_tf(rest);
        }
        3 => {
            let _ = cdr::decode_odometry(rest);
        }
        _ => unreachable!(),
    }
});
