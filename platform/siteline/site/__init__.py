"""A site: its CRS and site-local frame (``crs``), fence polygon (``fence``), class taxonomy
(``taxonomy``) and the spec that holds them (``spec``: ``SiteSpec``)."""
