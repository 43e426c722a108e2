"""Scan quality measured against the ground truth (simulation only).

- ``accuracy``  GroundTruth, Accuracy, accuracy: precision, recall and F at 2 and 5 mm, distances, chamfer
"""

from workbench.evaluation.accuracy import ACCURACY_COLUMNS, TAUS_MM, Accuracy, GroundTruth, accuracy, fscore

__all__ = ["ACCURACY_COLUMNS", "TAUS_MM", "Accuracy", "GroundTruth", "accuracy", "fscore"]
