"""Test-session set-up shared by every test package."""

# pymavlink chooses MAVLink 1 or 2 once, when mavutil is first imported, from MAVLINK20;
# missions sets it before that import (the project's one door to pymavlink). Importing it
# here first means no test module's own pymavlink import (mavwp ...) can make it MAVLink 1.
import holescan.missions  # noqa: F401
