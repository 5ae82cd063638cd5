"""Images and figures. Everything that draws lives here; the core never imports it."""
