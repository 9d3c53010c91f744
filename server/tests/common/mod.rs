//! Helpers shared by the integration tests.

#[allow(dead_code)] // only the web page's tests
pub mod browser;
#[allow(dead_code)] // the restart test talks to a child process without it
pub mod client;
#[allow(dead_code)]
pub mod postgres;
#[allow(dead_code)] // only the tests that run the binary
pub mod process;

/// The placement the command line writes for `scene` (GLB or summary bytes)
/// and `job` (JSON bytes): what the service must store byte for byte.
#[allow(dead_code)] // not every test binary compares placements
pub fn cli_placement(scene: &[u8], job: &[u8]) -> Vec<u8> {
    use optimizer::input::{GeometryUse, Load, SceneInput, Source};
    let job = optimizer::api::job::Job::from_json(job, "job").unwrap();
    let load = Load::new(
        Source::Bytes {
            bytes: scene,
            name: "scene",
        },
        GeometryUse::WhenNeeded,
    );
    let input = SceneInput::load(&load, &job, "job").unwrap();
    let out = input
        .prepare(&job, "job")
        .unwrap()
        .place(&Default::default(), &Default::default())
        .unwrap();
    optimizer::to_json_bytes(&out.placement).unwrap()
}

/// Starts the service with `cfg` on a free loopback port, in this test's
/// runtime; returns its address. With `IMPOSTOR_TEST_DATABASE=postgres`,
/// on a database of its own in the tests' PostgreSQL cluster.
#[allow(dead_code)] // the restart test runs the real binary instead
pub async fn start(mut cfg: server::Config) -> std::net::SocketAddr {
    // The database clients block: on a thread of their own, off the runtime.
    let state = std::thread::spawn(move || {
        if cfg.database.is_none() {
            cfg.database = postgres::database_for_tests();
        }
        server::AppState::open(cfg)
    })
    .join()
    .unwrap()
    .unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(server::run(listener, state, std::future::pending()));
    addr
}

/// The generated city (seed 1, no levels of detail) at `scale`, as a GLB.
#[allow(dead_code)]
pub fn city(scale: f64) -> Vec<u8> {
    optimizer::citygen::generate(&optimizer::citygen::CityParams {
        seed: 1,
        scale,
        lod: false,
        ..Default::default()
    })
    .unwrap()
}

/// The scene summary of the generated city at `scale`.
#[allow(dead_code)]
pub fn city_summary(scale: f64) -> serde_json::Value {
    serde_json::to_value(
        optimizer::scene::gltf_load::load_scene_bytes(&city(scale), "c")
            .unwrap()
            .summary(),
    )
    .unwrap()
}
