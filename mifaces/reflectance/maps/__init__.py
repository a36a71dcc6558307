"""Per-texel maps fitted with the region fits: the diffuse albedo (:mod:`.diffuse`), the
specular reflectance (:mod:`.specular`) and the normals (:mod:`.normals`, whose per-texel
step is :mod:`.normal_fit`'s)."""
