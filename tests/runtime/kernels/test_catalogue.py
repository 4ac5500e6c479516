"""The run's view of the catalogue (generated/manifest.json) agrees with the generator's, and each
kernel's metadata says truly whether its law's energy is quadratic in grad u."""
import pytest

from tensormass import backends, elements, laws
from tensormass.generator import catalogue as generator_catalogue
from tensormass.runtime.kernels import catalogue
from tensormass.runtime.kernels.kernels import kernel_source


def test_the_manifest_answers_what_the_generator_derives():
    built_in = laws.names(user=False) + laws.measure_names()
    for element in elements.names():
        for law in built_in:
            assert catalogue.quadratures(element, law) == generator_catalogue.quadratures(element, law), (element, law)


@pytest.mark.parametrize("element, law, quadrature", [
    ("tetra", "hooke", "gauss4"), ("hexahedron", "hooke", "exact"), ("tetra", "hybmss", "discrete"),
    ("shell", "hooke", "gauss1"), ("tetra", "no_such_law", "gauss1"), ("no_such_element", "hooke", "gauss1"),
    (None, "hooke", "gauss9"), (None, "cst_dkt", "gauss1")])
def test_a_refused_combination_gets_the_generators_message(element, law, quadrature):
    with pytest.raises(ValueError) as ours:
        catalogue.check(element, law, quadrature)
    with pytest.raises(ValueError) as theirs:
        generator_catalogue.entries(None if element is None else [element], [law], [quadrature])
    assert str(ours.value) == str(theirs.value)


@pytest.mark.parametrize("element, law, quadrature", [
    ("tetra", "hooke", "exact"), ("hexahedron", "neohookean", "gauss2"), ("hexahedron", "hybmss", "discrete"),
    ("shell", "cst_dkt", "exact"), (None, "stvk", "gauss3"), ("tetra10", "measure_volume", "gauss2")])
def test_an_existing_combination_passes(element, law, quadrature):
    catalogue.check(element, law, quadrature)
    generator_catalogue.entries(None if element is None else [element], [law], [quadrature])


def test_the_metadata_says_which_energies_are_quadratic():
    """The flag the assembly trusts to build K once and take f = -K u from it."""
    flags = {}
    for element, law, quadrature in catalogue.committed():
        for name in backends.names():
            meta = backends.get(name).read_metadata(kernel_source(element, law, quadrature, name))
            flags.setdefault(law, set()).add(meta["quadratic_energy"])
    expected = {law: {law in laws.names(user=False) and laws.is_quadratic(law)} for law in flags}
    assert flags == expected
    assert flags["hooke"] == {True} and flags["stvk"] == {False}
