"""heliquad's plant side: what stands in for the rig when there is no hardware."""

__all__ = []
