"""HID gloves and controllers: device profiles (data files), the pure report parser and the
hidapi source."""
from .profile import Profile, ProfileError, available_profiles, load_profile

__all__ = ["Profile", "ProfileError", "available_profiles", "load_profile"]
