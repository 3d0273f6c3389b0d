"""Spinner models: each turns a scene into departure states of granules leaving the disc."""
