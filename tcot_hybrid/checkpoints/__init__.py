"""Shipped planner checkpoints (safetensors weights + JSON metadata), chosen by robot name."""
