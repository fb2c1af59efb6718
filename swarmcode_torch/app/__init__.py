"""The application: run directories and checkpoints, records, reporters (TensorBoard, CSV,
progress), drawing, sweeps, Ray, the Python API and the command line. The only layer that knows
files, flags and TensorBoard tags."""
