"""The run scripts' options for the swappable links: --localizer, --planner, --follower.

And the particle filter's (--localize, --pf-param and the map check): each class is loaded, and
the parameters checked, before anything runs (one line, exit code 2). evaluate.py checks its
--localizer / --planner / --follower / --mapper with check_links too, and its --slam-param
with check_mapper_params.
"""
from __future__ import annotations

from typing import Any


def add_localization_options(parser) -> None:
    """--localize and the particle filter's --pf-param NAME:=VALUE, shared by the run scripts."""
    parser.add_argument("--localize", action="store_true", help="also run the particle filter "
                        "(/pose with localized); the wall follower keeps exploring "
                        "(stop_when_localized false) unless -p says otherwise")
    parser.add_argument("--pf-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="particle filter parameter override (repeatable), e.g. "
                        "--pf-param beams:=90")


# The links the scripts can swap (in the ROS graph each is a node parameter of the same name).
LINK_OPTIONS = {
    "localizer": "a localizer (amr_common.plugins.interfaces.Localizer), e.g. "
                 "examples.likelihood_mcl:LikelihoodFieldMcl",
    "planner": "a planner (amr_common.plugins.interfaces.Planner), e.g. "
               "examples.wavefront_planner:WavefrontPlanner",
    "follower": "a path follower (amr_common.plugins.interfaces.PathFollower), e.g. "
                "examples.plain_pursuit:PlainPursuit",
    "mapper": "a mapper (amr_common.plugins.interfaces.Mapper), e.g. "
              "examples.odometry_mapper:OdometryMapper",
}
RUN_SCRIPT_NEEDS = {"localizer": "--localize or --goal", "planner": "--goal",
                    "follower": "--goal"}


def add_link_options(parser, needs: dict[str, str] = RUN_SCRIPT_NEEDS) -> None:
    """--localizer, --planner, --follower MODULE:CLASS: the user's class for that link.

    needs: link -> the options it goes with (said in the help).
    """
    from amr_common.plugins.loader import LINKS
    for link, with_options in needs.items():
        parser.add_argument(f"--{link}", default=None, metavar="MODULE:CLASS",
                            help=f"with {with_options}: {LINK_OPTIONS[link]} (default "
                            f"{LINKS[link][1]})")


def check_links(given: dict[str, str | None], runs: dict[str, bool],
                needs_text: dict[str, str]) -> dict[str, str]:
    """Load every given link's class now: {link: MODULE:CLASS} of the given ones.

    PluginSpecError (one line) naming what a class lacks; ValueError for a link whose
    node or episode part does not run (`runs` False): "--planner needs --goal" (needs_text).
    """
    from amr_common.plugins.loader import load_class
    given = {link: spec for link, spec in given.items() if spec}
    for link, spec in given.items():
        if not runs[link]:
            raise ValueError(f"--{link} needs {needs_text[link]}")
        load_class(spec, link)
    return given


# The kinds of evaluate.py result sets and the links their episodes run (the navigation
# episodes' localizer only on the filter's pose).
RESULT_KINDS = {"wall_following": ("controller",),
                "localization": ("controller", "localizer"),
                "navigation": ("controller", "localizer", "planner", "follower"),
                "mapping": ("controller", "mapper")}


def links_ran(kind: str, given: dict[str, str | None], pose_source: str = "filter"
              ) -> dict[str, str]:
    """{link: MODULE:CLASS} of every link a `kind` of episodes ran: the given, else the project's.

    `given`: the user's classes by link (the controller's included), missing or None for the
    project's.
    """
    from amr_common.plugins.loader import LINKS
    return {link: given.get(link) or LINKS[link][1] for link in RESULT_KINDS[kind]
            if not (link == "localizer" and kind == "navigation" and pose_source != "filter")}


def check_link_options(args, needs: dict[str, bool]) -> dict[str, str]:
    """Load every --localizer / --planner / --follower class now; ValueError (one line).

    `needs`: link -> whether the run starts its node (an option for a link that does not run
    is refused). Returns {link: spec} of the given ones (the node parameters to set).
    """
    return check_links({link: getattr(args, link, None) for link in needs}, needs,
                       RUN_SCRIPT_NEEDS)


def check_mapper_params(items: list[str], mapper: str | None) -> dict[str, Any]:
    """evaluate.py's --slam-param NAME:=VALUE for the mapper's class: typed; ValueError.

    Names from the class's parameter_descriptions(); the project's Mapper checks the values
    here, another class when an episode builds it. (The run scripts' --slam-param also takes
    the slam node's own parameters: launch_slam.slam_overrides.)
    """
    from amr_common.plugins.loader import (
        DEFAULT_MAPPER,
        described_parameters,
        load_class,
        parse_overrides,
    )
    from amr_common.ros.parameters import typed_values
    overrides = parse_overrides(items)
    if mapper in (None, DEFAULT_MAPPER):
        from amr_mapping.mapper_params import check_parameters
        check_parameters(overrides)
        return overrides
    table = described_parameters(load_class(mapper, "mapper"))
    if table is None:  # the class lists no parameters: it checks them itself
        return overrides
    unknown = [name for name in overrides if name not in table]
    if unknown:
        raise ValueError(f"{', '.join(unknown)}: no such parameter of mapper {mapper}; "
                         f"known: {', '.join(sorted(table))}")
    overrides, problems = typed_values(table, overrides)
    if problems:
        raise ValueError("; ".join(problems))
    return overrides


def check_particle_filter(args, script: str, set_by_script: dict[str, str]) -> None:
    """--pf-param names and values, by the filter's and its node's own checks; ValueError."""
    if not args.pf_overrides:
        return
    if not (getattr(args, "localize", False) or getattr(args, "goal", None) is not None):
        raise ValueError("--pf-param needs --localize or --goal (no particle filter runs "
                         "without them)")
    from amr_common.plugins.loader import DEFAULT_LOCALIZER, link_parameters, load_class
    from amr_common.ros.parameters import typed_values
    from amr_localization.particle_filter_node_params import (
        node_parameter_problems,
        node_parameters,
    )
    from amr_localization.particle_filter_params import check_parameters
    from launch_common import _refused
    _refused("--pf-param", args.pf_overrides, script, set_by_script)
    node_table = node_parameters()
    spec = getattr(args, "links", {}).get("localizer", DEFAULT_LOCALIZER)
    PARAMETERS = link_parameters(load_class(spec, "localizer"), node_table)
    table = {**node_table, **PARAMETERS}
    unknown = [name for name in args.pf_overrides if name not in table]
    if unknown:
        with_class = "" if spec == DEFAULT_LOCALIZER else f" with localizer {spec}"
        raise ValueError(f"--pf-param {', '.join(unknown)}: no such particle filter parameter"
                         f"{with_class}; known: {', '.join(sorted(table))}")
    args.pf_overrides, problems = typed_values(table, args.pf_overrides)
    if not problems:
        node_values = {name: default for name, (default, _) in node_table.items()}
        node_values.update({k: v for k, v in args.pf_overrides.items() if k in node_table})
        problems = node_parameter_problems(node_values)
        try:  # the reference's own checks; another class checks when the node builds it
            if spec == DEFAULT_LOCALIZER:
                check_parameters({k: v for k, v in args.pf_overrides.items()
                                  if k in PARAMETERS})
        except ValueError as exc:
            problems.append(str(exc))
    if problems:
        raise ValueError(f"--pf-param: {'; '.join(problems)}")


def check_filter_map(world, pf_overrides: dict[str, Any], localizer: str | None = None) -> None:
    """The particle filter's checks against its map, before anything runs: ValueError (one line).

    A map too big for its memory budget (saying what it would need), an initial pose where the
    robot cannot be; with the filter's own parameters (--pf-param may also set its node's).
    A map whose table would take too long to build (saying how long). Up to ~0.5 s: only a
    sample of the table is built (the filter goes on from it). Only for the project's filter
    (`localizer` None or it): another localizer checks its map when its node builds it.
    """
    from amr_common.plugins.loader import DEFAULT_LOCALIZER
    if localizer not in (None, DEFAULT_LOCALIZER):
        return
    from amr_localization.particle_filter_params import PARAMETERS, check_parameters, check_world
    check_world(world, check_parameters(
        {name: value for name, value in pf_overrides.items() if name in PARAMETERS}))
