//! What our Kalman filter is compared with `adskalman` on.

/// The covariance forms compared with `adskalman`: (label, our criterion id, adskalman's id
/// (criterion and callgrind), our callgrind kernel).
pub const KF_FORMS: [(&str, &str, &str, &str); 2] = [
    ("Joseph", "ours", "adskalman", "kf"),
    (
        "optimal gain",
        "ours_standard",
        "adskalman_symmetric",
        "kf_standard",
    ),
];

/// The problems both filters step, as criterion and callgrind name them.
pub const KF_PROBLEMS: [&str; 2] = ["3x2_f64", "4x2_f32"];

/// The target: our step in at most this × `adskalman`'s time.
pub const KF_TARGET: f64 = 0.8;
