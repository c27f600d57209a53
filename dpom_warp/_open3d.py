"""Open3D, imported on first use: it takes about a second to import and only rendering,
ground fitting and .ply output need it (the engine, the kernels and cached scenes do not)."""


class _Open3D:
    def __getattr__(self, name):
        import open3d

        return getattr(open3d, name)


o3d = _Open3D()
