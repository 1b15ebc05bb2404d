"""Learning from demonstration: dataset snapshots, behaviour cloning, ONNX export, model archives, evaluation."""
