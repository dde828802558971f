"""The MCAP container, below the session format: defensive record framing (framing), the
damage-tolerant scan of a whole file (scan), the one-writer-per-file OS lock (lock), and the
rewrite of a cut-off or damaged file into a valid one (recover)."""
