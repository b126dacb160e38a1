"""Evaluation metrics: exact DTW (JAX), content / style errors (paper 000 §4.2), generation metrics.

References: Kuriyama et al. 2022, §4.2, eqs. 13-16; docs/design.md §5 for the ZeroEGGS metrics.
"""

from jaxgest.metrics.dtw import dtw, dtw_numpy, dtw_wavefront, path_distances
from jaxgest.metrics.generation import (
    beat_alignment,
    frechet_distance,
    frechet_distance_from_statistics,
    gaussian_smooth,
    gaussian_statistics,
    hand_speed,
    kinematic_beats,
    linear_probe_accuracy,
    linear_probe_predict,
    onset_times,
    shuffled_beat_alignment,
)
from jaxgest.metrics.transfer_errors import (
    arm_velocities,
    content_error,
    content_error_components,
    hands_metres,
    style_error,
    style_error_components,
    summarize_errors,
    window_for_fps,
    window_statistics,
)

__all__ = [
    "arm_velocities",
    "beat_alignment",
    "content_error",
    "content_error_components",
    "dtw",
    "dtw_numpy",
    "dtw_wavefront",
    "frechet_distance",
    "frechet_distance_from_statistics",
    "gaussian_smooth",
    "gaussian_statistics",
    "hand_speed",
    "hands_metres",
    "kinematic_beats",
    "linear_probe_accuracy",
    "linear_probe_predict",
    "onset_times",
    "path_distances",
    "shuffled_beat_alignment",
    "style_error",
    "style_error_components",
    "summarize_errors",
    "window_for_fps",
    "window_statistics",
]
