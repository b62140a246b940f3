"""``wafer-roadmap``: build or load a cell's roadmap and print its statistics."""

import argparse
import sys

from wafer_planner_ros.cli.common import add_roadmap_options, EXIT_OK, load_cell, roadmap_for
from wafer_planner_ros.cli.common import run, UsageError, write_json
from wafer_planner_ros.geometry.kinematics import elbow_words


def statistics(cell, cached) -> dict:
    """Return the roadmap statistics that the tool prints, as plain data."""
    roadmap = cached.roadmap
    components = roadmap.components
    sizes = {int(c): int((components == c).sum()) for c in set(components.tolist())}
    station_components = roadmap.station_component()
    joined = set().union(*station_components.values()) if station_components else set()
    return {
        'cell': cell.name,
        'cell_file': cell.source,
        'nodes': roadmap.node_count,
        'edges': roadmap.edge_count,
        'components': len(sizes),
        'largest_component': max(sizes.values()),
        'stations': {name: {'nodes': [node for _, node in entries],
                            'elbows': [elbow for elbow, _ in entries],
                            'components': sorted(station_components[name])}
                     for name, entries in roadmap.stations.items()},
        'stations_connected': len(joined) == 1,
        'samplers': roadmap.stats.get('samplers', {}),
        'candidate_edges': roadmap.stats.get('candidate_edges'),
        'clearance_evaluations': roadmap.stats.get('clearance_evaluations'),
        'build_time_s': roadmap.stats.get('build_time_s'),
        'load_time_s': cached.seconds,
        'cache_hit': cached.hit,
        'cache_status': cached.status.value,
        'cache_reason': cached.reason,
        'cache_file': None if cached.path is None else str(cached.path),
        'hash': roadmap.digest,
        'seed': roadmap.seed,
    }


def format_statistics(stats: dict) -> str:
    """Return the statistics as the tool's human-readable text."""
    connected = ('all in one component' if stats['stations_connected']
                 else 'NOT all in one component')
    lines = [
        f"cell          {stats['cell']} ({stats['cell_file']})",
        f"nodes         {stats['nodes']}",
        f"edges         {stats['edges']}",
        f"components    {stats['components']} (largest {stats['largest_component']} nodes)",
        'stations      ' + connected,
    ]
    for name, station in sorted(stats['stations'].items()):
        elbows = ', '.join(elbow_words(elbow) for elbow in station['elbows'])
        lines.append(f"  {name:<12}{elbows} -> nodes {station['nodes']}, "
                     f"component {station['components']}")
    lines.append('samplers      draws   nodes  failed  unused  merges  new  coverage  redundant'
                 '  weight')
    for name, c in stats['samplers'].items():
        lines.append(f"  {name:<10}{c['draws']:>7} {c['nodes']:>7} {c['failed']:>7} "
                     f"{c['discarded']:>7} {c['merges']:>7} {c['new_components']:>4} "
                     f"{c['coverage']:>9} {c['redundant']:>10} {c['weight']:>7.3f}")
    lines += [
        f"build time    {stats['build_time_s']:.2f} s "
        f"({stats['candidate_edges']} candidate edges, "
        f"{stats['clearance_evaluations']} clearance evaluations)",
        f"cache         {stats['cache_status']}"
        + (f" ({stats['cache_reason']})" if stats['cache_reason'] else '')
        + f", {stats['load_time_s']:.3f} s"
        + (f", {stats['cache_file']}" if stats['cache_file'] else ''),
        f"hash          {stats['hash']}",
        f"seed          {stats['seed']}",
    ]
    return '\n'.join(lines)


def main(argv=None) -> int:
    """Run wafer-roadmap."""
    parser = argparse.ArgumentParser(prog='wafer-roadmap', description=__doc__.split('\n')[0])
    add_roadmap_options(parser)
    parser.add_argument('--json', metavar='PATH|-', help='also write the statistics as JSON')
    parser.add_argument('--plot', metavar='PNG',
                        help='draw the cell with the robot at each station and the roadmap')
    args = parser.parse_args(argv)
    if args.nodes < 1:
        raise UsageError(f'--nodes must be >= 1, got {args.nodes}')
    cell = load_cell(args)
    cached = roadmap_for(args, cell)
    stats = statistics(cell, cached)
    if args.json:
        write_json(stats, args.json)
    if args.json != '-':
        print(format_statistics(stats))
    if args.plot:
        from wafer_planner_ros.plotting import plot_roadmap
        plot_roadmap(cell, cached.roadmap, args.plot)
        print(f'plot          {args.plot}', file=sys.stderr if args.json == '-' else sys.stdout)
    return EXIT_OK


def entry_point() -> int:
    """Console-script entry point."""
    return run(main)


if __name__ == '__main__':
    sys.exit(entry_point())
