"""Regression check of our own numbers (not a reference test): the trajectory hash of the
bundled decks is what it was before ``[initial_state.oem]`` existed (issue 13).  An STM file
records the hash of the deck it was built from and is refused for any other; a new
optional deck field must not change the hash of the decks that do not use it, or every STM
file an analyst built earlier would be refused as "another trajectory"."""

import pytest

from fracas.config.trajectory import load_deck, trajectory_hash

# computed at commit e9c7f9c (before the OEM option) with the same function
HASHES = {
    "leo_j2": "7a5f5e27cc6d9af0099405c61dca7497c86421f5f461633db1ffe4f8025935d9",
    "earth_mars_sep": "b8d3f06713405c79527fd84ebaaf2028d756f000628580fd2c664cdc1d8a95b2",
    "near_earth_spiral": "10ade340454b1c5add52263026fec01bbead34c5d43fe358573ea8538d16ce8e",
    "mercury_approach_traj": "3f815ade9babdbe20fbd28e28e57bc6623b93d396bf7bb3bbae376f700240c51",
}


@pytest.mark.parametrize("name", sorted(HASHES))
def test_hash_of_bundled_decks_unchanged(name):
    assert trajectory_hash(load_deck(f"namelists/{name}.toml")) == HASHES[name]
