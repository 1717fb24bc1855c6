"""Annotated RGB-D datasets: the COCO layout (:mod:`.coco`), real frames with a box CSV
imported (:mod:`.csvimport`), and the detector's AP on a dataset (:mod:`.evaluation`)."""

from holescan.ground.datasets.coco import (
    CATEGORY,
    Dataset,
    DatasetImage,
    Sample,
    check_box,
    load_dataset,
    load_image_pair,
    write_dataset,
)
from holescan.ground.datasets.csvimport import (
    FramePair,
    find_pairs,
    import_csv_dataset,
    read_box_csv,
)
from holescan.ground.datasets.evaluation import (
    JSON_SUFFIXES,
    PLOT_SUFFIXES,
    EvalReport,
    brier_score,
    calibration_outcomes,
    detect_image,
    evaluate_dataset,
    format_table,
    ground_truth,
    plot_pr,
    plot_reliability,
    run_detector,
    write_coco_results,
)

__all__ = [
    "CATEGORY",
    "JSON_SUFFIXES",
    "PLOT_SUFFIXES",
    "Dataset",
    "DatasetImage",
    "EvalReport",
    "FramePair",
    "Sample",
    "brier_score",
    "calibration_outcomes",
    "check_box",
    "detect_image",
    "evaluate_dataset",
    "find_pairs",
    "format_table",
    "ground_truth",
    "import_csv_dataset",
    "load_dataset",
    "load_image_pair",
    "plot_pr",
    "plot_reliability",
    "read_box_csv",
    "run_detector",
    "write_coco_results",
    "write_dataset",
]
