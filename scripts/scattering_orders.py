"""Tabulates scripts/scattering_orders.sh's renders: per direction, the
shares of Y (single scattering by quadrature, order 2, orders 3 and up) and
the per-sample relative variance of Y of the whole, of order 2 alone and of
orders 3 and up alone, all relative to the whole's Y (so that the last two
say what would be left if the other part were computed without noise).

    python3 scripts/scattering_orders.py RUNS_DIR SPP SKY...
"""
import json
import sys

ORDERS = ["0-99", "2-2", "3-99", "99-99"]


def main():
    runs, spp, skies = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
    for sky in skies:
        for sun in (91, 93, 96, 99):
            r = {}
            for o in ORDERS:
                with open(f"{runs}/{sky}-{sun}-{o}.json") as f:
                    r[o] = json.load(f)["directions"]
            print(f"{sky}, sun zenith {sun} deg")
            print("  zenith azimuth        Y  single%  order2%  order3+% | var: all  order2  order3+")
            for i, d in enumerate(r["0-99"]):
                y = d["xyz"][1]
                single = r["99-99"][i]["xyz"][1]
                o2 = r["2-2"][i]["xyz"][1] - single
                o3 = r["3-99"][i]["xyz"][1] - single

                def var(o):
                    return spp * (r[o][i]["xyz_stderr"][1] / y) ** 2

                print(
                    f"  {d['zenith_deg']:6.1f} {d['azimuth_deg']:7.0f} {y:10.4g} {100 * single / y:8.1f}"
                    f" {100 * o2 / y:8.1f} {100 * o3 / y:9.1f} | {var('0-99'):9.3g} {var('2-2'):7.3g} {var('3-99'):8.3g}"
                )


if __name__ == "__main__":
    main()
