"""Regenerate the bundled synthetic data set in jaxcable/data/.

    python scripts/make_bundled_data.py

The data are synthetic: Park et al.'s test protocol (10 cycles, a rest of 24/48/72 h,
a re-stretch) at 100 and 300 mm, 3 and 50 mm/min, 100 and 150 N, simulated with the
default IntegratedModel (Dyneema SK78 3 mm) plus one physical effect the model lacks
and measurement noise; see `jaxcable._papers.synthetic.bundled_dataset`.
"""

import pathlib

import jax


def main():
    jax.config.update("jax_enable_x64", True)
    import jaxcable as jc
    from jaxcable._papers.synthetic import bundled_dataset

    out = pathlib.Path(__file__).resolve().parent.parent / "jaxcable" / "data"
    out.mkdir(exist_ok=True)
    for old in out.glob("*.csv"):
        old.unlink()
    for test in bundled_dataset():
        path = out / f"{test.metadata['id']}.csv"
        jc.write_csv(path, test)
        print(f"wrote {path} ({test.time.shape[0]} samples)")


if __name__ == "__main__":
    main()
