"""One press: the MuJoCo scene, the force-limited drive, the skin read at 10 Hz, the best frame and
its labels; the calibration probe and a part's MJCF assets."""
