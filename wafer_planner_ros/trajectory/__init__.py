"""From a path to a verified timed curve: safe corridor, B-spline, timing, verification."""
