//! The demo's job (`scripts/demo.sh`), end to end with the real binaries: generate the sample, convert
//! it, inspect it, and check the region metadata through the shared schema types.

use residency_schemas::{HISTOGRAM_BINS, REGIONS_KEY, RegionMetadata};
use residency_tests::run;

#[test]
fn sample_converts_to_a_pyramid_with_complete_region_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let sample = dir.path().join("sample");
    let store = dir.path().join("sample.ome.zarr");
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    run(
        "ingest",
        &["sample", "-o", &s(&sample), "--size", "40,96,80", "--quiet"],
    );
    let inputs: Vec<String> = ["nuclei", "membranes", "filaments"]
        .iter()
        .map(|c| s(&sample.join(format!("{c}.ome.tif"))))
        .collect();
    let mut args: Vec<&str> = vec!["convert"];
    args.extend(inputs.iter().map(String::as_str));
    let out_path = s(&store);
    args.extend(["-o", &out_path, "--chunk", "16", "--quiet"]);
    let summary = String::from_utf8(run("ingest", &args).stdout).unwrap();
    assert!(summary.contains("(uint16)"), "{summary}");

    let root: serde_json::Value =
        serde_json::from_slice(&std::fs::read(store.join("zarr.json")).unwrap()).unwrap();
    let ome = &root["attributes"]["ome"];
    assert_eq!(ome["version"], "0.5");
    let labels: Vec<&str> = ome["omero"]["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["label"].as_str().unwrap())
        .collect();
    assert_eq!(labels, ["nuclei", "membranes", "filaments"]);
    assert_eq!(
        ome["multiscales"][0]["datasets"][0]["coordinateTransformations"][0]["scale"],
        serde_json::json!([1.0, 2.0, 0.5, 0.5])
    );

    let regions: RegionMetadata =
        serde_json::from_value(root["attributes"][REGIONS_KEY].clone()).unwrap();
    assert_eq!(regions.brick_shape, [16, 16, 16]);
    assert_eq!(regions.histogram_bins, HISTOGRAM_BINS);
    assert_eq!(regions.channels.len(), 3);
    // Sparse sample: level 0 has empty bricks, and every brick is accounted for.
    let l0 = &regions.levels[0];
    assert!(l0.bricks_empty > 0);
    let bricks: u64 = l0.shape.iter().map(|s| s.div_ceil(16)).product::<u64>() * 3;
    assert_eq!(l0.bricks_written + l0.bricks_empty, bricks);
    for level in &regions.levels {
        assert_eq!(level.minmax.last().unwrap().grid_shape, [1, 1, 1]);
        for grid in &level.minmax {
            assert!(
                store.join(&grid.path).join("zarr.json").exists(),
                "{}",
                grid.path
            );
        }
        assert!(store.join(&level.histogram).join("zarr.json").exists());
    }
    for c in &regions.channels {
        assert_eq!(c.voxels, 40 * 96 * 80);
        assert_eq!(c.nan_voxels, 0);
        assert!(c.histogram_edges.windows(2).all(|w| w[0] < w[1]));
        assert!(c.histogram_edges[0] <= c.min.unwrap());
        assert!(*c.histogram_edges.last().unwrap() > c.max.unwrap());
    }
    // The nuclei are 16-bit and bright; the 8-bit channels were promoted exactly.
    assert!(regions.channels[0].max.unwrap() > 1000.0);
    assert!(regions.channels[1].max.unwrap() <= 255.0);

    let inspect = String::from_utf8(run("ingest", &["inspect", &out_path]).stdout).unwrap();
    assert!(
        inspect.contains("axes: c, z (micrometer), y (micrometer), x (micrometer)"),
        "{inspect}"
    );
    assert!(inspect.contains("channel 'nuclei'"), "{inspect}");
}
