"""The detector's training side: auto-labelled datasets rendered by the simulator, their labels, the
ground-truth oracle detector, and YOLO training and inference-model optimisation.

Modules are imported on their own (``from app.training.dataset import build_dataset``); this package
imports nothing, so the optional ``[train]`` extra (ultralytics, torch, onnx) is never loaded with it.
"""
