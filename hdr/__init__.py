"""HDR imaging: camera-response recovery (one module per method), radiance
merge, exposure alignment, tone mapping and HDR file formats."""
