"""Fence databases kept current: the build keeps its features (``--store``), ``update`` applies OpenStreetMap changes to them."""
