"""Files: the frame format, the crash-safe recording reader, CSV/NPZ readers, output checks."""
