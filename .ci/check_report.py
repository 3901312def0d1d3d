"""CI: the report.html that a demo wrote opens in headless Chromium with no console error, its
metrics table equals metrics.json, every video loads, the scrubber draws a chosen tick, and the
plots are there.

usage: python check_report.py OUT_DIR
"""
import json
import os
import pathlib
import sys


def main() -> int:
    from playwright.sync_api import sync_playwright

    from pibr.bench.processes import chromium_path

    out = sys.argv[1]
    metrics = json.load(open(os.path.join(out, "metrics.json")))["methods"]
    problems, errors = [], []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium_path(), args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(pathlib.Path(out, "report.html").resolve().as_uri())
        cells = page.evaluate("""Array.from(document.querySelectorAll('#metrics td')).map(td =>
            [td.closest('tr').dataset.method, td.dataset.key, td.dataset.value])""")
        for method, key, value in cells:
            want = metrics[method][key]
            if (want is None) != (value == "") or (want is not None and float(value) != want):
                problems.append(f"table {method} {key}: {value!r} against metrics.json's {want!r}")
        if {m for m, _, _ in cells} != set(metrics):
            problems.append(f"table methods {sorted({m for m, _, _ in cells})} against {sorted(metrics)}")
        page.wait_for_function("Array.from(document.querySelectorAll('video')).every(v => v.readyState >= 2)",
                               timeout=30000)
        last = next(iter(metrics.values()))["frames"] - 1
        page.fill("#tick", str(last))
        page.dispatch_event("#tick", "input")
        page.wait_for_function(f"Array.from(document.querySelectorAll('#scrubber canvas')).every(c => "
                               f"c.dataset.tick === '{last}' && c.width > 0)", timeout=30000)
        plots = page.locator(".plot").count()
        if plots < 4:
            problems.append(f"{plots} plots over time, expected DSSIM, PSNR, age and client ms at least")
        browser.close()
    problems += [f"console: {e}" for e in errors]
    print(f"  report.html: {len(cells)} table cells equal metrics.json, scrubber at tick {last}, {plots} plots")
    if problems:
        print(f"{out}/report.html: " + "; ".join(problems), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
