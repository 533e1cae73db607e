"""Filter algebra (FRACAS PROP, FILTER, KSGAIN, WLSGAN, DYNO, DERY): pure functions of arrays."""
