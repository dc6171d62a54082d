"""Numbers published by Albini & Cannata (IJRR 2020) that we know, for side-by-side tables.

Only values quoted in our issues are recorded; every other cell of the paper's tables is shown as
"unknown" (``None``) rather than guessed. Accuracies in %, times in ms per image.
"""

from __future__ import annotations

#: Table 3: HandsNet hand / non-hand accuracy and time per image.
HANDSNET_ACCURACY_PCT = 97.81
HANDSNET_MS_PER_IMAGE = 12.6
#: Table 8: SegNet pixel accuracy, mean IoU and time per image.
SEGNET_ACC_PCT = 93.37
SEGNET_MIOU_PCT = 89.17
SEGNET_MS_PER_IMAGE = 63.0
#: Table 13 (Test B): HandsNet accuracy with 60 % of the taxels removed.
HANDSNET_ACCURACY_60PCT_REMOVED = 92.67

#: Test B, classification accuracy (%) by fraction of taxels removed; None = unknown to us.
TEST_B_CLASSIFICATION_PCT: dict[float, float | None] = {
    0.1: None,
    0.2: None,
    0.3: None,
    0.4: None,
    0.5: None,
    0.6: HANDSNET_ACCURACY_60PCT_REMOVED,
    0.7: None,
}
