"""A dataset's cartography options (units, index contours, attribute names, schedule override, the sea, depth
labels, label orientation), kept in its stored build parameters under ``cartography`` (docs/design.md section 9)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from engine.cartography.schedule import check_index_every, check_units, make_schedule, parse_schedule
from engine.errors import InvalidParameter
from engine.intervals import INDEX_EVERY

#: Attribute naming conventions: ccsm's own (``elevation``) and maplibre-contour's (``ele``).
ATTRIBUTE_NAMES = ("ccsm", "maplibre-contour")
#: Key of the options in a dataset's stored parameters.
PARAMS_KEY = "cartography"
#: What becomes of the 0 m line: left out (as Martin does), drawn as a coastline, or kept as a contour.
SEA_CHOICES = ("drop", "coastline", "keep")
#: How negative levels are labelled: "-200 m", or "200 m" (a depth below the datum).
DEPTH_LABELS = ("negative", "below-datum")
#: Which way label text turns: its top toward higher ground, or always upright (docs/design.md section 9.3).
LABEL_ORIENTATIONS = ("uphill", "upright")


def check_choice(name: str, value: object, choices: tuple[str, ...]) -> str:
    """``value`` (case and spaces aside) if it is one of ``choices``, else raise naming the option."""
    if isinstance(value, str) and value.strip().lower() in choices:
        return value.strip().lower()
    raise InvalidParameter(f"{name} must be one of {', '.join(choices)}, got {value!r}")


def check_attribute_names(value: object) -> str:
    """``value`` if it is one of ATTRIBUTE_NAMES, else raise naming it."""
    return check_choice("attribute_names", value, ATTRIBUTE_NAMES)


@dataclass(frozen=True)
class CartographyOptions:
    """How a dataset's contours are drawn and named.

    Attributes
    ----------
    units
        Vertical unit of the elevations, "m", "ft" or "fm" (fathoms; None: not given, found from the source or metres).
    index_every
        Index contours are every n-th base interval.
    attribute_names
        "ccsm" (``elevation``) or "maplibre-contour" (``ele``).
    schedule
        Override table of the interval schedule (``STEP:HIDE_SCALE,...,STEP``), or None for the default rule.
    attribution
        Who made the data, for TileJSON (None: the source file's name).
    sea
        One of SEA_CHOICES: the 0 m line left out of tiles and labels ("drop"), drawn as a coastline (its
        features carry ``coastline: true``), or kept as an ordinary contour.
    depth_labels
        One of DEPTH_LABELS: negative levels labelled "-200 m" or "200 m".
    label_orientation
        One of LABEL_ORIENTATIONS.
    """

    units: str | None = None
    index_every: int = INDEX_EVERY
    attribute_names: str = "ccsm"
    schedule: str | None = None
    attribution: str | None = None
    sea: str = "drop"
    depth_labels: str = "negative"
    label_orientation: str = "uphill"

    def checked(self) -> CartographyOptions:
        """The same options, validated and normalised (raises InvalidParameter naming the bad one)."""
        if self.schedule is not None:
            parse_schedule(self.schedule)
        return CartographyOptions(
            None if self.units is None else check_units(self.units),
            check_index_every(self.index_every),
            check_attribute_names(self.attribute_names),
            None if self.schedule is None else self.schedule.strip(),
            self.attribution,
            check_choice("sea", self.sea, SEA_CHOICES),
            check_choice("depth_labels", self.depth_labels, DEPTH_LABELS),
            check_choice("label_orientation", self.label_orientation, LABEL_ORIENTATIONS),
        )

    @property
    def elevation_key(self) -> str:
        """The name of the elevation attribute in tiles."""
        return "ele" if self.attribute_names == "maplibre-contour" else "elevation"

    def as_params(self) -> dict[str, Any]:
        """The options as stored in a dataset's parameters (the sea, depth labels and label orientation only
        when they differ from the defaults, so content hashes of datasets built before them stay as they were)."""
        params: dict[str, Any] = {
            "units": self.units,
            "index_every": self.index_every,
            "attribute_names": self.attribute_names,
            "schedule": self.schedule,
            "attribution": self.attribution,
        }
        defaults = CartographyOptions()
        for key in ("sea", "depth_labels", "label_orientation"):
            if getattr(self, key) != getattr(defaults, key):
                params[key] = getattr(self, key)
        return params

    @classmethod
    def from_params(cls, params: dict[str, Any]) -> CartographyOptions:
        """The options stored in a dataset's parameters (defaults for a dataset stored without them)."""
        stored = params.get(PARAMS_KEY) or {}
        return cls(
            units=stored.get("units"),
            index_every=int(stored.get("index_every") or INDEX_EVERY),
            attribute_names=stored.get("attribute_names") or "ccsm",
            schedule=stored.get("schedule"),
            attribution=stored.get("attribution"),
            sea=stored.get("sea") or "drop",
            depth_labels=stored.get("depth_labels") or "negative",
            label_orientation=stored.get("label_orientation") or "uphill",
        )


def check_schedule_fits(options: CartographyOptions | None, interval: float | None, source_scale: float) -> None:
    """Refuse a schedule override that is well formed but does not fit the data, before anything is built or
    stored: its first step must divide the data's contour interval, and its first hide scale must lie beyond
    the source scale (a rank has to be fully drawn at the source scale and fade over a range of scales).

    Parameters
    ----------
    options
        The dataset's cartography options (None or no override: nothing to check).
    interval
        The data's contour interval, in the options' units (None: a single level).
    source_scale
        Scale denominator of the data (where every level is fully drawn).

    Raises
    ------
    InvalidParameter
        Naming the ``schedule`` parameter, the entry and what is wrong with it.
    """
    if options is None or options.schedule is None:
        return
    checked = options.checked()
    # The latitude only turns scales into zooms; whether the table fits does not depend on it.
    make_schedule(
        interval,
        start_scale=source_scale,
        latitude=0.0,
        units=checked.units or "m",
        index_every=checked.index_every,
        override=checked.schedule,
    )
