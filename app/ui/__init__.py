"""viser scene layers and GUI panels (thin: they only draw core state and queue commands)."""
