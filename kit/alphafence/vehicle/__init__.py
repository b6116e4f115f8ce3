"""Talking to the vehicle: fence upload/download and fence parameters, through MAVSDK."""
