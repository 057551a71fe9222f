"""Blob extraction in regions of interest (issue 4): connected components, sub-pixel centroid and area."""
from swarmhil.agent.blob.blobs import Blobs, blobs_in_stack, exact_blobs, extract_blobs, extract_blobs_full

__all__ = ["Blobs", "blobs_in_stack", "exact_blobs", "extract_blobs", "extract_blobs_full"]
