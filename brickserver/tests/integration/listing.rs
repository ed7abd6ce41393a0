//! The dataset listing: JSON or HTML by `Accept`, the links' base URL (`--public-url`,
//! `X-Forwarded-*`, `Host`), and the neuroglancer link's state (scheme per Zarr version,
//! dimensions, each channel's display range and colour), parsed back from the link.

use std::collections::BTreeMap;

use residency_brickserver::neuroglancer::{
    self, Blend, Dimension, ImageLayer, Invlerp, LayerKind, SHADER, ShaderControls,
    SpatialDimensions, State,
};
use residency_brickserver::{PublicUrl, ServerOptions};
use residency_schemas::server::{DatasetEntry, DatasetList};

use crate::common::{BROWSER_ACCEPT, get, server, v2_store, v3_store};

/// A router for `cells` (v3, two channels) and `old` (v2, one channel), no viewer.
async fn two_stores(dir: &std::path::Path, options: &ServerOptions) -> axum::Router {
    let cells = v3_store(dir, "cells");
    let old = v2_store(dir, "old");
    server(&[("cells", &cells), ("old", &old)], options).await
}

/// The listing at `path` with `headers`, as JSON.
async fn listing(router: &axum::Router, path: &str, headers: &[(&str, &str)]) -> Vec<DatasetEntry> {
    let r = get(router, path, headers).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), "application/json");
    r.json::<DatasetList>().datasets
}

#[tokio::test]
async fn json_for_programs_and_html_for_browsers() {
    let dir = tempfile::tempdir().unwrap();
    let router = two_stores(dir.path(), &ServerOptions::default()).await;
    let host = [("host", "data.lab:8000")];
    let json = listing(&router, "/datasets", &host).await;
    assert_eq!(
        json.iter().map(|d| d.name.as_str()).collect::<Vec<_>>(),
        ["cells", "old"]
    );
    for accept in [
        None,
        Some("*/*"),
        Some("application/json"),
        Some("application/json, text/html"),
    ] {
        let mut headers = host.to_vec();
        headers.extend(accept.map(|a| ("accept", a)));
        assert_eq!(listing(&router, "/", &headers).await, json, "{accept:?}");
        let r = get(&router, "/", &headers).await;
        assert_eq!(r.header("vary"), "Accept");
    }
    // `/datasets` is always JSON.
    let with_browser = [("host", "data.lab:8000"), ("accept", BROWSER_ACCEPT)];
    assert_eq!(listing(&router, "/datasets", &with_browser).await, json);
    let r = get(&router, "/", &with_browser).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), "text/html; charset=utf-8");
    assert_eq!(r.header("vary"), "Accept");
    let page = r.text();
    assert!(page.starts_with("<!doctype html>"), "{page}");
    // Each dataset: its name, size, levels, channels and type, and its links; the Residency
    // viewer's relative (so a path prefix survives), the others absolute and escaped.
    for (d, facts) in json.iter().zip([
        "<td>cells</td><td>64 × 32 × 16</td><td>2</td><td>2</td><td>uint16</td>",
        "<td>old</td><td>8 × 6 × 4</td><td>1</td><td>1</td><td>uint8</td>",
    ]) {
        assert!(page.contains(facts), "{facts} in {page}");
        let view = format!(
            "<a href=\"{}/view\">open in the Residency viewer</a>",
            d.name
        );
        assert!(page.contains(&view), "{view} in {page}");
        for link in [&d.neuroglancer, &d.vizarr, &d.url] {
            let escaped = link.replace('&', "&amp;").replace('"', "&quot;");
            assert!(
                page.contains(&format!("href=\"{escaped}\"")),
                "{link} in {page}"
            );
        }
    }
    assert_eq!(page.matches("open in the Residency viewer").count(), 2);
    assert_eq!(page.matches(">neuroglancer</a>").count(), 2);
    assert_eq!(page.matches(">vizarr</a>").count(), 2);
}

#[tokio::test]
async fn the_page_escapes_what_it_shows() {
    let dir = tempfile::tempdir().unwrap();
    let options = ServerOptions {
        public_url: Some("https://example.org/a&b<c>'".parse::<PublicUrl>().unwrap()),
        ..ServerOptions::default()
    };
    let router = two_stores(dir.path(), &options).await;
    let page = get(&router, "/", &[("accept", "text/html")]).await.text();
    assert!(
        page.contains("href=\"https://example.org/a&amp;b&lt;c&gt;&#39;/cells/\""),
        "{page}"
    );
    assert!(
        page.contains(">store: https://example.org/a&amp;b&lt;c&gt;&#39;/cells/</a>"),
        "{page}"
    );
    assert!(!page.contains("<c>"), "{page}");
}

#[tokio::test]
async fn links_follow_the_public_url_then_forwarded_headers_then_host() {
    let dir = tempfile::tempdir().unwrap();
    let check = |d: &DatasetEntry, base: &str| {
        assert_eq!(d.url, format!("{base}/{}/", d.name));
        assert_eq!(d.view, format!("{base}/{}/view", d.name));
        assert_eq!(
            d.vizarr,
            format!(
                "https://hms-dbmi.github.io/vizarr/?source={base}/{}/",
                d.name
            )
        );
        let state = neuroglancer::parse_link(&d.neuroglancer).unwrap();
        let scheme = if d.name == "old" { "zarr" } else { "zarr3" };
        for layer in &state.layers {
            assert_eq!(layer.source, format!("{scheme}://{base}/{}/", d.name));
        }
    };
    let router = two_stores(dir.path(), &ServerOptions::default()).await;
    let cases: [(&[(&str, &str)], &str); 7] = [
        (&[("host", "data.lab:8000")], "http://data.lab:8000"),
        (
            &[
                ("host", "127.0.0.1:8000"),
                ("x-forwarded-proto", "https"),
                ("x-forwarded-host", "proxy.example.org"),
            ],
            "https://proxy.example.org",
        ),
        // A chain of proxies: the first value of each is the client's.
        (
            &[
                ("host", "127.0.0.1:8000"),
                ("x-forwarded-proto", "HTTPS, http"),
                ("x-forwarded-host", "outer.example.org:8443, inner:80"),
            ],
            "https://outer.example.org:8443",
        ),
        // Only the scheme forwarded: the Host stays.
        (
            &[("host", "data.lab"), ("x-forwarded-proto", "https")],
            "https://data.lab",
        ),
        // Nonsense is ignored: an unknown scheme, a host that is no host.
        (
            &[
                ("host", "data.lab"),
                ("x-forwarded-proto", "javascript"),
                ("x-forwarded-host", "evil\"><script>"),
            ],
            "http://data.lab",
        ),
        (&[("host", "[::1]:8000")], "http://[::1]:8000"),
        (&[], "http://localhost"),
    ];
    for (headers, base) in cases {
        let items = listing(&router, "/datasets", headers).await;
        assert_eq!(items.len(), 2);
        for d in &items {
            check(d, base);
        }
        // `/` (JSON) builds the same links.
        assert_eq!(listing(&router, "/", headers).await, items);
    }
    // --public-url wins over every header, and keeps its path prefix.
    let options = ServerOptions {
        public_url: Some("https://data.example.org/residency/".parse().unwrap()),
        ..ServerOptions::default()
    };
    let router = two_stores(dir.path(), &options).await;
    let headers = [
        ("host", "127.0.0.1:8000"),
        ("x-forwarded-proto", "http"),
        ("x-forwarded-host", "other"),
    ];
    for d in &listing(&router, "/datasets", &headers).await {
        check(d, "https://data.example.org/residency");
    }
}

/// The layer the state gives a channel of `cells`.
fn cells_layer(
    name: &str,
    base: &str,
    position: f64,
    controls: ShaderControls,
    visible: bool,
) -> ImageLayer {
    ImageLayer {
        kind: LayerKind::Image,
        name: name.to_string(),
        source: format!("zarr3://{base}/cells/"),
        local_dimensions: BTreeMap::from([("c'".to_string(), Dimension(1.0, String::new()))]),
        local_position: vec![position],
        shader: SHADER.to_string(),
        shader_controls: controls,
        opacity: 1.0,
        blend: Blend::Additive,
        visible,
    }
}

#[tokio::test]
async fn neuroglancer_states_carry_version_dimensions_ranges_and_colours() {
    let dir = tempfile::tempdir().unwrap();
    let router = two_stores(dir.path(), &ServerOptions::default()).await;
    let items = listing(&router, "/datasets", &[("host", "h:1")]).await;
    let base = "http://h:1";
    // OME-Zarr 0.5 (Zarr v3), two uint16 channels in micrometres: zarr3://, one layer per
    // channel at its own local position, with the omero window and colour; GFP is inactive.
    let cells = neuroglancer::parse_link(&items[0].neuroglancer).unwrap();
    let expected = State {
        dimensions: Some(SpatialDimensions {
            x: Dimension(2.5e-7, "m".into()),
            y: Dimension(5e-7, "m".into()),
            z: Dimension(2e-6, "m".into()),
        }),
        layers: vec![
            cells_layer(
                "cells DAPI",
                base,
                0.5,
                ShaderControls {
                    normalized: Some(Invlerp {
                        range: [100.0, 3000.0],
                        window: Some([0.0, 65535.0]),
                    }),
                    color: "#0000ff".into(),
                },
                true,
            ),
            cells_layer(
                "cells GFP",
                base,
                1.5,
                ShaderControls {
                    normalized: Some(Invlerp {
                        range: [250.0, 40000.0],
                        window: Some([0.0, 65535.0]),
                    }),
                    color: "#00ff00".into(),
                },
                false,
            ),
        ],
    };
    assert_eq!(cells, expected);
    // OME-Zarr 0.4 (Zarr v2), one uint8 channel without units: zarr://, dimensions unitless.
    let old = neuroglancer::parse_link(&items[1].neuroglancer).unwrap();
    assert_eq!(
        old.dimensions,
        Some(SpatialDimensions {
            x: Dimension(1.0, String::new()),
            y: Dimension(1.0, String::new()),
            z: Dimension(1.0, String::new()),
        })
    );
    assert_eq!(old.layers.len(), 1);
    let layer = &old.layers[0];
    assert_eq!(layer.source, format!("zarr://{base}/old/"));
    assert_eq!(layer.name, "old gray");
    assert_eq!(layer.local_position, [0.5]);
    assert_eq!(
        layer.shader_controls,
        ShaderControls {
            normalized: Some(Invlerp {
                range: [10.0, 200.0],
                window: Some([0.0, 255.0]),
            }),
            color: "#ffffff".into(),
        }
    );
    // The raw JSON, as neuroglancer reads it: dimensions in x, y, z order, `c'` local.
    let link = &items[0].neuroglancer;
    let fragment = link
        .strip_prefix("https://neuroglancer-demo.appspot.com/#!")
        .unwrap();
    let json = percent_encoding::percent_decode_str(fragment)
        .decode_utf8()
        .unwrap();
    assert!(
        json.starts_with(r#"{"dimensions":{"x":[2.5e-7,"m"],"y":[5e-7,"m"],"z":[2e-6,"m"]},"layers":[{"type":"image","name":"cells DAPI","source":"zarr3://http://h:1/cells/","localDimensions":{"c'":[1.0,""]},"localPosition":[0.5],"#),
        "{json}"
    );
    assert!(
        json.contains(r##""shaderControls":{"normalized":{"range":[100.0,3000.0],"window":[0.0,65535.0]},"color":"#0000ff"},"opacity":1.0,"blend":"additive","visible":true}"##),
        "{json}"
    );
}

#[tokio::test]
async fn a_store_without_readable_metadata_is_still_listed() {
    let dir = tempfile::tempdir().unwrap();
    let broken = dir.path().join("broken.ome.zarr");
    std::fs::create_dir(&broken).unwrap();
    let router = server(&[("broken", &broken)], &ServerOptions::default()).await;
    let items = listing(&router, "/datasets", &[("host", "h")]).await;
    let state = neuroglancer::parse_link(&items[0].neuroglancer).unwrap();
    // The version is left to neuroglancer (zarr:// reads v2 and v3), with its defaults.
    assert_eq!(state.dimensions, None);
    assert_eq!(state.layers.len(), 1);
    assert_eq!(state.layers[0].source, "zarr://http://h/broken/");
    assert_eq!(state.layers[0].shader_controls.normalized, None);
    let page = get(&router, "/", &[("accept", "text/html")]).await.text();
    assert!(
        page.contains("<td>broken</td><td>?</td><td>?</td><td>?</td><td>?</td>"),
        "{page}"
    );
}

#[test]
fn why_level_0_or_a_link_is_unreadable_is_said() {
    use residency_brickserver::dataset_store::DatasetStore;
    use residency_brickserver::listing::StoreSummary;
    let dir = tempfile::tempdir().unwrap();
    let cells = v3_store(dir.path(), "cells");
    let store = || {
        use residency_store::location::StoreLocation;
        let location = StoreLocation::Folder(cells.clone());
        DatasetStore::open(&location, None).unwrap()
    };
    std::fs::remove_file(cells.join("0/zarr.json")).unwrap();
    let summary = StoreSummary::read(&store()).unwrap();
    assert_eq!(
        summary.level0.unwrap_err().to_string(),
        format!("{}/0/zarr.json: missing", cells.display())
    );
    std::fs::write(cells.join("0/zarr.json"), "{").unwrap();
    let summary = StoreSummary::read(&store()).unwrap();
    assert!(
        summary
            .level0
            .unwrap_err()
            .to_string()
            .starts_with(&format!("{}/0/zarr.json: ", cells.display())),
    );

    assert_eq!(
        neuroglancer::parse_link("https://example.org/#!{}")
            .unwrap_err()
            .to_string(),
        "not a neuroglancer link: https://example.org/#!{}"
    );
    let not_a_state = format!("{}#!%7B%22layers%22%3A1%7D", neuroglancer::APP_URL);
    assert_eq!(
        neuroglancer::parse_link(&not_a_state)
            .unwrap_err()
            .to_string(),
        "invalid type: integer `1`, expected a sequence at line 1 column 11: {\"layers\":1}"
    );
}
