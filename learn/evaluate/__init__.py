"""The evaluation stage: a checkpoint scored on a test split, and the report beside the paper's
Tables 3 and 8."""
