"""Chapter 4 — answers to the CONCEPT and DESIGN questions, computed from their formulas."""


def _sigma_z(Z, f, sigma, B):
    """Depth uncertainty of two-view triangulation: σZ = Z² σ / (f B)."""
    return Z ** 2 * sigma / (f * B)


def _pairs(n):
    """Exhaustive matching: every unordered pair once, N (N − 1) / 2."""
    return n * (n - 1) / 2


# 4.1  Z = 5 m, f = 800 px, σ = 0.5 px, baseline 0.5 m and 1 m (the seed's worked example: 3.1 cm, 1.6 cm)
sigma_z = [_sigma_z(5, 800, 0.5, 0.5), _sigma_z(5, 800, 0.5, 1.0)]

# 4.2  COLMAP (pycolmap 4.2.1's IncrementalPipelineOptions().mapper): PnP RANSAC threshold abs_pose_max_error (px),
#      abs_pose_min_num_inliers, filter_min_tri_angle (°), filter_max_reproj_error (px)
colmap_thresholds = [12.0, 30.0, 1.5, 4.0]

# 4.3  pairs for 100 and 10,000 images
exhaustive_pairs = [_pairs(100), _pairs(10_000)]

# 4.22 hours of matching at 30 ms per pair, 10,000 images: exhaustive, retrieval top-50 (N k pairs)
matching_hours = [_pairs(10_000) * 0.03 / 3600, 10_000 * 50 * 0.03 / 3600]

# 4.23 incremental or global, scenarios (a)-(d)
sfm_choice = ["incremental", "global", "global", "incremental"]

# 4.24 how many times fewer pairs retrieval (top-20) matches than exhaustive at 1M images
pair_reduction_1m = _pairs(1e6) / (1e6 * 20)
