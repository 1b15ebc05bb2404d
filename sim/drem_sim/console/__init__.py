"""DeepRacer console (TensorFlow 1 frozen graph) models: node names, conversion to ONNX, and writing them."""
