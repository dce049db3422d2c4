"""Synthetic worlds and sensors with known truth, for the demo and for accuracy tests."""
