"""MuJoCo scenes, sensorized parts, contactors, the skin model and dataset generation.

Uses tactile/ for layouts and maps; never imported by tactile/ or learn/.
"""
