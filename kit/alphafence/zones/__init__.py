"""Where zones come from: every zone reader (OpenStreetMap, GeoJSON and its streams, ED-269
and ED-318, KML and KMZ, OpenAir), the tag rules that say which features are restricted and
how, and the easy mistakes caught on the way in. What a reader gives is restricted features
(:class:`~alphafence.zones.features.Feature`), for :mod:`alphafence.fencing` to fence."""
