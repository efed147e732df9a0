"""Export trained policies to ONNX files that carry the deploy contract (deploy/contract.py) in their metadata."""
