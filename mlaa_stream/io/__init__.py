"""Reading and writing frames: video (PyAV), images (OpenImageIO), folders and sequences, progress."""
