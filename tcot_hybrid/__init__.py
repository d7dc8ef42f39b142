"""tcot-hybrid: TCoT (trajectory chain-of-thought + GLSR) as a classical-control hybrid."""

__version__ = "0.1.0"
