"""Geotagging (pure): detections + camera + vehicle pose -> hole positions; merging sightings."""

from geotag._types import VehiclePose

__all__ = ["VehiclePose"]
