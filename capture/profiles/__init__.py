"""Shipped HID device profiles (TOML data files, read by `capture.hid.profile`)."""
