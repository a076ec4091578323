"""Stage 2, views: what a method sees of a place, rendered from a data source.

`mapconfig` (the settings), `localmap` (the sliding local map of scans), `topview` (its
rasterisation and encodings), `bevdensity` (BEVPlace's point-density images), `noise` (the
viewpoint-noise conditions T{a}R{b}), `resample` (image resampling: moved viewpoints, a
method's input size), `mapbuild` (one pass over a sequence's scans), `render` (the views of any
source: scans through `mapbuild`, image folders by resampling) and `mapcache` (rendered views
kept on disk, keyed by the source's fingerprint).
"""
