"""`swarmdsl plot`: pictures of metrics, from run folders and sweep tables (matplotlib)."""
