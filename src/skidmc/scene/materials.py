"""Materials: named targets with sourced density, heat capacity and conductivity.

``make_scene(preset="paper-quartz", target="steel")`` sets the three ``target.*`` keys from the
entry ``"steel"`` of :data:`MATERIALS`; a ``target.*`` key given explicitly still wins. The same
works as ``skidmc height --preset paper-quartz --set target=steel``, as ``target = "steel"`` in a
study file's ``[scene]`` or ``[[scenes]]`` table, and ``skidmc materials`` lists the entries.

Values are near room temperature (300 K), written as unit strings in the units of their source,
so that an entry reads as its source prints it. Each entry names its source (book, table) and
says how far other sources or grades spread. Adding a material is adding one :class:`Material`
to :data:`_ENTRIES`; the tests check that every entry converts and builds a valid scene.

Sources
-------
- Incropera, DeWitt, Bergman & Lavine, *Fundamentals of Heat and Mass Transfer*, 6th ed.
  (Wiley, 2007), Appendix A: Table A.1 (metallic solids), A.2 (nonmetallic solids), A.3
  (common materials), properties at 300 K. Cited as "Incropera Table A.x".
- The Los Alamos report "Effect of Target Thermal Conductivity and Roughness on the Initiation
  of PBX 9404 by Oblique Impact", Table VI (the values its calculations used; k in
  cal/s-cm-degC, read per kelvin: see :mod:`skidmc.scene.presets`). Cited as "report Table VI".
- ASTM D2442 / IEC 60672-3 alumina grades, typical values as compiled in Shackelford & Doremus
  (eds.), *Ceramic and Glass Materials: Structure, Properties and Processing* (Springer, 2008).
- USDA Forest Products Laboratory, *Wood Handbook*, FPL-GTR-190 (2010), ch. 4 (thermal
  properties of wood) and ch. 5, Table 5-3a (side hardness, Janka, at 12 % moisture; compression
  perpendicular to the grain).
- ACI 318-19, *Building Code Requirements for Structural Concrete*, Sec. 22.8 (bearing strength
  of concrete under a loaded area smaller than the support: 0.85 f'c sqrt(A2/A1), at most
  2 x 0.85 f'c), and ACI 302.1R, *Guide to Concrete Floor and Slab Construction* (floor slabs
  specified at about 3000-5000 psi).
- Tabor, *The Hardness of Metals* (Oxford, 1951): the mean pressure of a fully plastic
  indentation is the indentation hardness, about 3 times the uniaxial flow stress.

Hardness (``target.hardness``, docs/model.md "Targets softer than the billet"): the billet's
flow stress in the report is 28,000 psi (193 MPa; 34,400 psi, 237 MPa, in its second series).
Metals, ceramics, glasses and rock indent at pressures far above that (Vickers hardness of
plain carbon steel and aluminium 2024-T6 about 1.2-2 GPa, copper 0.4-0.9 GPa, soda-lime glass
about 5.5 GPa, fused silica about 9 GPa, alumina 12-20 GPa; granite's uniaxial crushing
strength 130-250 MPa, its confined indentation pressure several times that): they are
``"rigid"``, the report's target, and nothing changes for them. Annealed pure gold is the
closest, about 250 MPa (Vickers 25), still above both series' billets; electroplated gold, the
report's, is harder.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from collections.abc import Mapping

import numpy as np

from skidmc.errors import SceneError
from skidmc.scene.keys import SI_UNITS
from skidmc.scene.units import to_si

__all__ = [
    "MATERIALS",
    "PROPERTY_TABLES",
    "PropertyTable",
    "TABLE_REFERENCE_TEMPERATURE",
    "format_table",
    "parse_table",
    "table_text",
    "STACKS",
    "STACK_SEPARATOR",
    "Stack",
    "format_layers",
    "is_stack",
    "parse_layers",
    "target_values",
    "MATERIAL_KEY",
    "TARGET_KEYS",
    "Material",
    "get_material",
    "list_materials",
]

#: The pseudo-key naming a material in :func:`~skidmc.scene.make_scene` and study files.
MATERIAL_KEY = "target"

#: The scene keys a material sets.
TARGET_KEYS: tuple[str, ...] = ("target.density", "target.heat_capacity", "target.conductivity",
                                "target.hardness")


#: Why a metal, ceramic, glass or rock is "rigid" (the module docstring gives the values).
RIGID_REASON = ("indentation hardness far above any billet's flow stress (metals 0.25-2 GPa, "
                "glasses and ceramics 5-20 GPa, granite's confined crushing pressure several "
                "times its 130-250 MPa uniaxial strength; the report's billets 193-237 MPa): "
                "the report's rigid target")


@dataclasses.dataclass(frozen=True)
class Material:
    """A named target material.

    Attributes
    ----------
    name : str
        Registry name (``"steel"``), the value of ``target = ...``.
    description : str
        What the material is (grade, temper, form).
    density, heat_capacity, conductivity : str
        Unit strings, in the units of the source [mass / volume, energy / (mass temperature),
        power / (length temperature)].
    source : str
        Book (or report) and table the three values come from.
    spread : str
        How far other sources, grades or conditions move the values.
    hardness : str
        The contact pressure at which the target yields under the billet (``target.hardness``)
        [pressure]: a unit string for a material softer than some billets (its indentation
        hardness or confined crushing strength), ``"rigid"`` for one whose hardness lies far above
        any billet's flow stress (metals, ceramics, glasses, rock: the report's rigid target),
        ``"elastic"`` for one that deforms elastically to large strains without yielding
        (rubber), which the plastic-contact model cannot describe.
    hardness_source : str
        Where the hardness (or the reason for ``"rigid"`` / ``"elastic"``) comes from, and its
        spread.
    """

    name: str
    description: str
    density: str
    heat_capacity: str
    conductivity: str
    source: str
    spread: str
    hardness: str = "rigid"
    hardness_source: str = RIGID_REASON

    @property
    def values(self) -> dict[str, str]:
        """The scene overrides: :data:`TARGET_KEYS` -> unit strings (or ``"rigid"``,
        ``"elastic"`` for the hardness)."""
        return dict(zip(TARGET_KEYS, (self.density, self.heat_capacity, self.conductivity,
                                      self.hardness)))

    @property
    def elastic(self) -> bool:
        """Whether the material is elastic (``hardness == "elastic"``): refused by the solver."""
        return self.hardness == "elastic"


_INCROPERA = ("Incropera, DeWitt, Bergman & Lavine, Fundamentals of Heat and Mass Transfer, "
              "6th ed. (2007)")
_REPORT = ("LA report 'Effect of Target Thermal Conductivity and Roughness on the Initiation of "
           "PBX 9404 by Oblique Impact'")

_ENTRIES: tuple[Material, ...] = (
    # --- metals --------------------------------------------------------------------------------
    Material(
        "gold", "pure gold",
        "19300 kg/m^3", "129 J/(kg K)", "317 W/(m K)",
        f"{_INCROPERA}, Table A.1 (gold, 300 K)",
        "pure metal: handbooks agree within a few percent; impurities (electroplated or alloyed "
        "gold) lower k."),
    Material(
        "gold-report", "the report's gold target, as its calculations took it",
        "19.3 g/cm^3", "0.0316 cal/g/K", "7.03e-1 cal/s/cm/K",
        f"{_REPORT}, Table VI (gold)",
        "k = 294 W/(m K), 7 % below handbook gold (317 W/(m K), Incropera Table A.1). The real "
        "target was 3 mil of gold on 7 mil of copper on Dural (report Sec. III); see docs/"
        "inputs.md for why its effective k lies between Dural and copper."),
    Material(
        "copper", "pure copper",
        "8933 kg/m^3", "385 J/(kg K)", "401 W/(m K)",
        f"{_INCROPERA}, Table A.1 (copper, pure, 300 K)",
        "commercial and electroplated coppers a few percent lower; copper alloys far lower "
        "(cartridge brass 110, bronzes about 50 W/(m K), same table)."),
    Material(
        "aluminium-2024", "aluminium alloy 2024-T6 (Al-4.5Cu-1.5Mg-0.6Mn, 'Dural')",
        "2770 kg/m^3", "875 J/(kg K)", "177 W/(m K)",
        f"{_INCROPERA}, Table A.1 (aluminum alloy 2024-T6, 300 K)",
        "k depends on temper: ASM Handbook Vol. 2 (Properties and Selection: Nonferrous Alloys) "
        "lists about 120 W/(m K) for 2024-T3/T4 sheet, about 150 for T6 and about 190 "
        "annealed (O); pure aluminium is 237 W/(m K) (Incropera Table A.1)."),
    Material(
        "steel", "plain carbon steel (Mn <= 1 %, Si <= 0.1 %)",
        "7854 kg/m^3", "434 J/(kg K)", "60.5 W/(m K)",
        f"{_INCROPERA}, Table A.1 (plain carbon steel, 300 K)",
        "AISI 1010 63.9 W/(m K); medium-carbon and low-alloy steels about 40-50 W/(m K) "
        "(same table)."),
    Material(
        "stainless-304", "austenitic stainless steel AISI 304",
        "7900 kg/m^3", "477 J/(kg K)", "14.9 W/(m K)",
        f"{_INCROPERA}, Table A.1 (AISI 304, 300 K)",
        "other austenitic grades 13-15 W/(m K) (AISI 316 13.4, AISI 347 14.2, same table)."),
    # --- ceramics and glasses ------------------------------------------------------------------
    Material(
        "alumina-99.5", "dense high-purity polycrystalline alumina (99.5 % grades approach it)",
        "3970 kg/m^3", "765 J/(kg K)", "36.0 W/(m K)",
        f"{_INCROPERA}, Table A.2 (aluminum oxide, polycrystalline, 300 K)",
        "the table's density is alumina's theoretical one; commercial 99.5 % grades are "
        "slightly porous (about 3.9 g/cm^3) and list up to about 30 W/(m K), lower purities "
        "less (ASTM D2442 grades, see alumina-94). Sapphire: 46 W/(m K) (Incropera Table A.2)."),
    Material(
        "alumina-94", "93-95 % alumina (ASTM D2442 Type II, IEC 60672-3 C-786)",
        "3.7 g/cm^3", "900 J/(kg K)", "19 W/(m K)",
        "ASTM D2442 Type II / IEC 60672-3 C-786 typical values, as compiled in Shackelford & "
        "Doremus (eds.), Ceramic and Glass Materials (Springer, 2008)",
        "engineering alumina grades from about 85 to 99.5 % span 14-30 W/(m K) and "
        "870-940 J/(kg K) near room temperature (same compilation)."),
    Material(
        "alumina-85", "85 % alumina (IEC 60672-3 C-780, 80-86 % alumina; the report's grade)",
        "3.40 g/cm^3", "765 J/(kg K)", "15 W/(m K)",
        "k: ASTM D2442 / IEC 60672-3 85 % grades, 14-16 W/(m K) at room temperature, as "
        "compiled in Shackelford & Doremus (eds.), Ceramic and Glass Materials (Springer, 2008); "
        f"density: {_REPORT}, Table VI (the Coors grade); c: {_INCROPERA}, Table A.2 "
        "(aluminum oxide, 300 K)",
        "k 14-16 W/(m K) between makers; with temperature it takes dense alumina's fall "
        "(Incropera Table A.2, scaled), an upper bound on the fall: the grade's glassy phase "
        "conducts better when hot (no table of the grade found)"),
    Material(
        "alumina-85-report", "the report's 85 % alumina (Coors; 15 % silica, magnesia, calcia)",
        "3.40 g/cm^3", "0.18 cal/g/K", "2.1e-2 cal/s/cm/K",
        f"{_REPORT}, Table VI (aluminum oxide) and Sec. III (grade)",
        "k = 8.8 W/(m K): below every handbook alumina grade (14-30 W/(m K), ASTM D2442 grades); "
        "the report does not say where its value comes from."),
    Material(
        "fused-quartz", "fused quartz (vitreous silica)",
        "2220 kg/m^3", "745 J/(kg K)", "1.38 W/(m K)",
        f"{_INCROPERA}, Table A.2 (silicon dioxide, polycrystalline (fused silica), 300 K)",
        "k rises with temperature: about 1.1 W/(m K) at 200 K and 1.5 at 400 K in the same "
        "table, so handbook values near room temperature read 1.1-1.4 W/(m K)."),
    Material(
        "quartz-report", "the report's fused-quartz target, as its calculations took it",
        "2.67 g/cm^3", "0.188 cal/g/K", "4.05e-3 cal/s/cm/K",
        f"{_REPORT}, Table VI (quartz)",
        "k = 1.69 W/(m K), above handbook fused quartz at room temperature (1.38 W/(m K) at "
        "300 K, Incropera Table A.2; the table reaches 1.69 only between 400 and 600 K); the "
        "density is crystalline quartz's (2650 kg/m^3, same table), not fused silica's (2220)."),
    Material(
        "soda-lime-glass", "soda-lime plate glass",
        "2500 kg/m^3", "750 J/(kg K)", "1.4 W/(m K)",
        f"{_INCROPERA}, Table A.3 (glass, plate (soda lime), 300 K)",
        "composition-dependent; other compilations give c about 840 J/(kg K) (Callister, "
        "Materials Science and Engineering, Table B.8)."),
    # --- building materials and others ---------------------------------------------------------
    Material(
        "concrete", "concrete, stone mix",
        "2300 kg/m^3", "880 J/(kg K)", "1.4 W/(m K)",
        f"{_INCROPERA}, Table A.3 (concrete (stone mix), 300 K)",
        "aggregate and moisture move k by tens of percent; c 850-1150 J/(kg K) (Callister, "
        "Table B.8).",
        "6800 psi",
        ("ACI 318-19 Sec. 22.8: bearing strength 2 x 0.85 f'c under a small loaded area, with "
        "f'c = 4000 psi, a usual specified strength of floor slabs (ACI 302.1R); "
        "f'c 3000-5000 psi gives 35-59 MPa; the unconfined crushing strength f'c itself "
        "(21-34 MPa) is the lower bound; a higher pressure heats more, so the confined value is "
        "the conservative choice")),
    Material(
        "granite", "granite (Barre)",
        "2630 kg/m^3", "775 J/(kg K)", "2.79 W/(m K)",
        f"{_INCROPERA}, Table A.3 (granite, Barre, 300 K)",
        "rocks vary with their mineral content: the same table's limestone, marble, sandstone "
        "and quartzite span about 2-5.4 W/(m K)."),
    Material(
        "oak", "hardwood (oak, maple), across the grain",
        "720 kg/m^3", "1255 J/(kg K)", "0.16 W/(m K)",
        f"{_INCROPERA}, Table A.3 (structural building materials, hardwoods (oak, maple))",
        "k varies about 20 % between species and rises with density and moisture; along the "
        "grain it is 1.5-2.8 times the value across (USDA Wood Handbook, FPL-GTR-190, ch. 4).",
        "60 MPa",
        ("USDA Wood Handbook, FPL-GTR-190 (2010), Table 5-3a: side (Janka) hardness of white "
        "oak 6.0 kN at 12 % moisture, the load that embeds an 11.28-mm ball to half its "
        "diameter, i.e. over a projected area of 1 cm^2: 60 MPa mean pressure; "
        "northern red oak 5.7 kN (57 MPa), sugar maple 6.4 kN (64 MPa), same table; "
        "compression perpendicular to the grain yields first at about 7 MPa (proportional "
        "limit, same table), and the Janka pressure includes the densification after it; the "
        "higher pressure heats more, so it is the conservative choice")),
    Material(
        "pine", "softwood (fir, pine), across the grain",
        "510 kg/m^3", "1380 J/(kg K)", "0.12 W/(m K)",
        f"{_INCROPERA}, Table A.3 (structural building materials, softwoods (fir, pine))",
        "as oak: about 20 % between species, 1.5-2.8 times higher along the grain (USDA Wood "
        "Handbook, ch. 4).",
        "32 MPa",
        ("USDA Wood Handbook, FPL-GTR-190 (2010), Table 5-3a: side (Janka) hardness of "
        "Douglas-fir (coast) 3.2 kN at 12 % moisture over a projected area of 1 cm^2; "
        "loblolly pine 3.1 kN, ponderosa pine 2.0 kN, eastern white pine 1.7 kN (17 MPa), same "
        "table; the hardest common softwood is the conservative choice")),
    Material(
        "rubber", "soft vulcanized rubber (as a rubber floor covering)",
        "1100 kg/m^3", "2010 J/(kg K)", "0.13 W/(m K)",
        f"{_INCROPERA}, Table A.3 (rubber, vulcanized, soft, 300 K)",
        "hard rubber 1190 kg/m^3 and 0.16 W/(m K) (same table); fillers in floor tiles raise "
        "density and k.",
        "elastic",
        ("soft vulcanized rubber deforms elastically to strains of several hundred percent "
        "(Young's modulus about 1-10 MPa) and does not flow plastically at a contact pressure; "
        "refused by the solver: the report's model (constant-pressure plastic contact, "
        "heat from sliding at that pressure) does not describe an elastic mat, which a "
        "billet's impact compresses through to the floor beneath")),
)

#: Name -> :class:`Material`, in the order above.
MATERIALS: Mapping[str, Material] = {m.name: m for m in _ENTRIES}


@dataclasses.dataclass(frozen=True)
class PropertyTable:
    """A material's conductivity and heat capacity against temperature, as its source prints
    them (docs/targets.md, "Temperature-dependent properties").

    Attributes
    ----------
    temperature : tuple of float
        [K].
    conductivity : tuple of float
        k [W/(m K)] at each temperature.
    heat_capacity : tuple of float or None
        c [J/(kg K)] at each temperature; None where the source gives none.
    source : str
    """

    temperature: tuple[float, ...]
    conductivity: tuple[float, ...]
    heat_capacity: tuple[float | None, ...]
    source: str

    def ratio(self, temperature: float, reference: float = 300.0) -> tuple[float, float]:
        """(k(T) / k(T_ref), c(T) / c(T_ref)), linear interpolation in the table [1]; only the
        temperatures where the table gives c are used for c."""

        t = np.asarray(self.temperature)
        k = np.asarray(self.conductivity)
        have_c = [i for i, c in enumerate(self.heat_capacity) if c is not None]
        tc = t[have_c]
        cc = np.asarray([self.heat_capacity[i] for i in have_c])
        return (float(np.interp(temperature, t, k) / np.interp(reference, t, k)),
                float(np.interp(temperature, tc, cc) / np.interp(reference, tc, cc)))


_ALUMINA_TABLE = PropertyTable(
    (100.0, 200.0, 300.0, 400.0, 600.0, 800.0, 1000.0, 1200.0, 1500.0, 2000.0),
    (133.0, 55.0, 36.0, 26.4, 15.8, 10.4, 7.85, 6.55, 5.66, 6.00),
    (None, None, 765.0, 940.0, 1110.0, 1180.0, 1225.0, None, None, None),
    f"{_INCROPERA}, Table A.2 (aluminum oxide, polycrystalline)")

#: Temperature tables of the registry's materials that have one (Incropera Table A.2; the
#: 300 K column is the entry's constant value). A target named by one of these materials takes
#: k(T) and c(T) from it where its scene needs them (``target.table``; docs/targets.md,
#: "Temperature-dependent properties"): the table sets the *shape*, k(T) = k_scene k_tab(T) /
#: k_tab(300 K) and likewise c, so that a scene's (or a study's sampled) ``target.conductivity``
#: and ``target.heat_capacity`` stay the values at 300 K. ``alumina-85`` takes dense alumina's
#: shape (no table of the 85 % grade was found; its glassy phase flattens the fall, so this is
#: the steepest reading).
PROPERTY_TABLES: Mapping[str, PropertyTable] = {
    "alumina-99.5": _ALUMINA_TABLE,
    "alumina-85": _ALUMINA_TABLE,
    "fused-quartz": PropertyTable(
        (100.0, 200.0, 300.0, 400.0, 600.0, 800.0, 1000.0, 1200.0),
        (0.69, 1.14, 1.38, 1.51, 1.75, 2.17, 2.87, 4.00),
        (None, None, 745.0, 905.0, 1040.0, 1105.0, 1155.0, 1195.0),
        f"{_INCROPERA}, Table A.2 (silicon dioxide, polycrystalline (fused silica))"),
}

#: The temperature [K] at which a table's values are the registry entry's constants (and a
#: scene's target.conductivity / target.heat_capacity apply): Incropera's 300 K column.
TABLE_REFERENCE_TEMPERATURE = 300.0


def format_table(reference: float, rows) -> str:
    """The canonical ``target.table`` text (SI, exact float reprs): ``"T_ref | T k c | T k c |
    ..."`` with T [K], k [W/(m K)], c [J/(kg K)], T increasing."""
    return " | ".join([repr(float(reference))]
                      + [" ".join(repr(float(x)) for x in row) for row in rows])


def parse_table(text: str) -> tuple[float, tuple[tuple[float, float, float], ...]]:
    """``target.table`` -> (T_ref [K], rows (T [K], k [W/(m K)], c [J/(kg K)])).

    Raises
    ------
    SceneError
        Not the canonical form (:func:`format_table`), fewer than two rows, temperatures not
        increasing, a value not finite and positive, or T_ref outside the table.
    """
    key = "target.table"
    parts = [p.strip() for p in text.split("|")]
    try:
        reference = float(parts[0])
        rows = tuple(tuple(float(x) for x in p.split()) for p in parts[1:])
    except ValueError:
        raise SceneError(key, text, "expected 'T_ref | T k c | T k c | ...' in SI units (K, "
                         "W/(m K), J/(kg K)); name a material with a table instead, e.g. "
                         "target = \"fused-quartz\"") from None
    if len(rows) < 2 or any(len(r) != 3 for r in rows):
        raise SceneError(key, text, "a table needs at least two rows of three numbers "
                         "(T [K], k [W/(m K)], c [J/(kg K)])")
    values = [reference, *(v for r in rows for v in r)]
    if not all(math.isfinite(v) and v > 0.0 for v in values):
        raise SceneError(key, text, "every value must be finite and > 0")
    temps = [r[0] for r in rows]
    if any(b <= a for a, b in zip(temps, temps[1:])):
        raise SceneError(key, text, "the temperatures must increase")
    if not temps[0] <= reference <= temps[-1]:
        raise SceneError(key, text, f"the reference temperature {reference!r} K lies outside "
                         f"the table ({temps[0]!r}-{temps[-1]!r} K)")
    return reference, rows


def table_text(name: str) -> str:
    """The canonical ``target.table`` of registry material `name` (:data:`PROPERTY_TABLES`),
    empty where it has none: every temperature the source gives k or c at, each property
    interpolated linearly where the source gives the other only, and held at its first or last
    value beyond the temperatures where the source gives it (so the piecewise-linear function
    of the rows is each property's own interpolant)."""
    table = PROPERTY_TABLES.get(name)
    if table is None:
        return ""
    t = np.asarray(table.temperature, dtype=float)
    have_c = [i for i, c in enumerate(table.heat_capacity) if c is not None]
    c = np.interp(t, t[have_c], [table.heat_capacity[i] for i in have_c])
    rows = zip(t.tolist(), [float(k) for k in table.conductivity], c.tolist())
    return format_table(TABLE_REFERENCE_TEMPERATURE, rows)


def list_materials() -> list[str]:
    """Names of the materials, in the order of :data:`MATERIALS`."""
    return list(MATERIALS)


def get_material(name: object) -> Material:
    """The material called `name`.

    Parameters
    ----------
    name : str
        A key of :data:`MATERIALS`.

    Returns
    -------
    Material

    Raises
    ------
    SceneError
        `name` is not a material name; the message (key ``target``) suggests close matches and
        lists the materials.
    """
    if isinstance(name, str) and name in MATERIALS:
        return MATERIALS[name]
    if not isinstance(name, str):
        raise SceneError(MATERIAL_KEY, name, "expected a material name (skidmc materials lists "
                         "them: " + ", ".join(MATERIALS) + ")")
    close = difflib.get_close_matches(name.strip().lower(), list(MATERIALS), n=3, cutoff=0.5)
    hint = ("did you mean " + " or ".join(repr(c) for c in close) + "? ") if close else ""
    raise SceneError(MATERIAL_KEY, name,
                     f"unknown material; {hint}materials: " + ", ".join(MATERIALS)
                     + "; stacks: " + ", ".join(STACKS) + " (or layers written 'gold 3 mil / "
                     "copper 7 mil / aluminium-2024')")


# --- layered targets (docs/targets.md) -----------------------------------------------------------

#: The pseudo-key's separator between layers of a stack: a slash with spaces around it (unit
#: strings such as "kg/m^3" have none).
STACK_SEPARATOR = " / "

_SPLIT = re.compile(r"\s+/\s+")
_MIL = re.compile(r"\bmils?\b")


@dataclasses.dataclass(frozen=True)
class Stack:
    """A named layered target.

    Attributes
    ----------
    name : str
        Registry name, the value of ``target = ...``.
    layers : str
        The stack as it would be written (``"gold 3 mil / copper 7 mil / aluminium-2024"``).
    description, source : str
        What it is, and where its layers and thicknesses come from.
    """

    name: str
    layers: str
    description: str
    source: str


_STACK_ENTRIES: tuple[Stack, ...] = (
    Stack(
        "gold-stack-report", "gold 3 mil / copper 7 mil / aluminium-2024",
        "the report's gold target: 3 mil (76 um) of gold electroplated on 7 mil (178 um) of "
        "copper on a 0.25-in. Dural sheet (taken semi-infinite: it is 35 times the copper's "
        "heated depth)",
        f"{_REPORT}, Sec. III (the targets); layer properties from the registry's gold, "
        "copper and aluminium-2024 (Incropera Table A.1; the Dural's temper is not given, "
        "see aluminium-2024's spread)"),
)

#: Name -> :class:`Stack`.
STACKS: Mapping[str, Stack] = {s.name: s for s in _STACK_ENTRIES}


def _layer_values(text: str, last: bool) -> tuple[dict[str, str], float]:
    """One layer of a stack: (the four target keys -> unit strings, thickness [m] or inf)."""
    text = text.strip()
    brace = re.fullmatch(r"\{([^}]*)\}\s*(.*)", text)
    if brace is not None:
        props = [p.strip() for p in brace[1].split(",")]
        if len(props) != 3:
            raise SceneError(MATERIAL_KEY, text, "explicit layer properties are written "
                             "{density, heat capacity, conductivity} with units, e.g. "
                             "{8933 kg/m^3, 385 J/(kg K), 401 W/(m K)} 7 mil")
        values = dict(zip(TARGET_KEYS, (*props, "rigid")))
        rest = brace[2].strip()
    else:
        name, _, rest = text.partition(" ")
        values = get_material(name).values
        rest = rest.strip()
    if last:
        if rest:
            raise SceneError(MATERIAL_KEY, text, "the last layer of a stack is semi-infinite: "
                             "give it no thickness")
        return values, math.inf
    if not rest:
        raise SceneError(MATERIAL_KEY, text, "every layer but the last needs a thickness, "
                         "e.g. 'gold 3 mil'")
    thickness = to_si(MATERIAL_KEY, _MIL.sub("thou", rest), "m")  # pint's "mil" is an angle
    if not (math.isfinite(thickness) and thickness > 0.0):
        raise SceneError(MATERIAL_KEY, text, "a layer's thickness must be > 0")
    return values, thickness


def format_layers(top_thickness: float, deeper: list[tuple[float, float, float, float]]
                  ) -> str:
    """The canonical ``target.layers`` text (SI, exact float reprs): ``"d1 | rho c k d | ... |
    rho c k"``."""
    parts = [repr(float(top_thickness))]
    for rho, c, k, d in deeper:
        nums = [rho, c, k] + ([d] if math.isfinite(d) else [])
        parts.append(" ".join(repr(float(x)) for x in nums))
    return " | ".join(parts)


def parse_layers(text: str) -> tuple[float, tuple[tuple[float, float, float, float], ...]]:
    """``target.layers`` -> (top thickness [m], deeper layers (rho [kg/m^3], c [J/(kg K)],
    k [W/(m K)], thickness [m], inf for the last)).

    Raises
    ------
    SceneError
        Not the canonical form (:func:`format_layers`), or a value not finite and positive.
    """
    key = "target.layers"
    parts = [p.strip() for p in text.split("|")]
    try:
        top = float(parts[0])
        rows = [tuple(float(x) for x in p.split()) for p in parts[1:]]
    except ValueError:
        raise SceneError(key, text, "expected 'd1 | rho c k d | ... | rho c k' in SI units "
                         "(name a stack with target = \"gold 3 mil / copper 7 mil / "
                         "aluminium-2024\")") from None
    if not rows:
        raise SceneError(key, text, "a stack needs at least one layer beneath the top")
    deeper = []
    for i, row in enumerate(rows):
        last = i == len(rows) - 1
        if len(row) != (3 if last else 4):
            raise SceneError(key, text, f"layer {i + 2} needs density, heat capacity, "
                             "conductivity" + ("" if last else " and thickness")
                             + (" (the last layer is semi-infinite: no thickness)" if last
                                else ""))
        deeper.append(row + ((math.inf,) if last else ()))
    for x in (top, *(v for row in deeper for v in row)):
        if not (x > 0.0 and not math.isnan(x)):
            raise SceneError(key, text, "every value must be > 0")
    if not math.isfinite(top) or any(not math.isfinite(v) for row in deeper for v in row[:3]):
        raise SceneError(key, text, "every value must be finite")
    return top, tuple(deeper)


def is_stack(name: object) -> bool:
    """Whether ``target = name`` names a stack (a registry stack, or layers written with
    :data:`STACK_SEPARATOR`)."""
    return isinstance(name, str) and (name in STACKS or _SPLIT.search(name.strip()) is not None)


def target_values(name: object) -> dict[str, str | float]:
    """The scene values ``target = name`` sets: the four target keys of the (top) material, as
    unit strings, ``target.layers`` (canonical text; empty for one material) and
    ``target.table`` (a material's temperature table, :func:`table_text`; empty for a stack,
    whose layers keep constant properties).

    Parameters
    ----------
    name : str
        A material (:data:`MATERIALS`), a stack (:data:`STACKS`), or a stack written out:
        layers from the surface down separated by " / ", each a material name or
        ``{density, heat capacity, conductivity}`` with units, followed by its thickness; the
        last layer without one (semi-infinite): ``"gold 3 mil / copper 7 mil /
        aluminium-2024"`` ("mil" is a thousandth of an inch).

    Raises
    ------
    SceneError
        Unknown names, a missing or extra thickness (key ``target``).
    """
    if not is_stack(name):
        return {**get_material(name).values, "target.layers": "",
                "target.table": table_text(name)}
    text = STACKS[name].layers if name in STACKS else name.strip()
    parts = _SPLIT.split(text)
    layers = [_layer_values(p, i == len(parts) - 1) for i, p in enumerate(parts)]
    deeper = []
    for values, thickness in layers[1:]:
        rho, c, k = (to_si(key, values[key], SI_UNITS[key]) for key in TARGET_KEYS[:3])
        deeper.append((rho, c, k, thickness))
    top_values, top_thickness = layers[0]
    return {**top_values, "target.layers": format_layers(top_thickness, deeper),
            "target.table": ""}

