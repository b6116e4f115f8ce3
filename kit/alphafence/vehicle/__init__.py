"""Talking to the vehicle, bottom up:

=================  ============================================================================
``keys``           signing key files, passphrase keys, signing timestamps
``bridge``         the signed MAVLink link, and the loopback bridge that gives MAVSDK one
``signing``        installing a key on the vehicle (SETUP_SIGNING) and confirming it
``link``           opening a MAVSDK link to the autopilot (through the bridge when signing)
``fence_transfer`` fence upload and download (MAVLink mission protocol), checked item by item
``params``         fence parameter profiles, set and read back
=================  ============================================================================
"""
