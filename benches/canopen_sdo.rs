#![allow(missing_docs)]
//! SDO throughput (CiA 301 §7.2.4): upload of a 4 kB object, segmented (one request per 7
//! bytes) vs block (127 segments per acknowledgement), client and server passing frames
//! directly (`canopen_sdo_upload_4k`) and over the in-process virtual CAN bus, each side on its
//! own endpoint (`canopen_sdo_upload_4k_virtual_bus`). Criterion's throughput line reports
//! bytes/s of object data.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use fieldprobe::bus::can::{CanBus, CanFrame, VirtualCan, VirtualEndpoint};
use fieldprobe::bus::canopen::sdo::{ObjectAccess, SdoClient, SdoServer, TransferMode};
use fieldprobe::units::Nanos;
use std::time::Duration;

const SIZE: usize = 4096;

struct Od(Vec<u8>);

impl ObjectAccess for Od {
    fn read(&mut self, _index: u16, _sub: u8) -> Result<Vec<u8>, u32> {
        Ok(self.0.clone())
    }
    fn write(&mut self, _index: u16, _sub: u8, data: &[u8]) -> Result<(), u32> {
        self.0 = data.to_vec();
        Ok(())
    }
}

/// One upload, frames handed over until the client has its result.
fn upload(client: &mut SdoClient, server: &mut SdoServer, od: &mut Od) -> usize {
    let now = Nanos::ZERO;
    let mut to_server: Vec<CanFrame> = client.upload(0x2000, 1, now);
    while !to_server.is_empty() {
        let mut to_client = Vec::new();
        for f in &to_server {
            to_client.extend(server.handle(f, od, now));
        }
        to_server.clear();
        for f in &to_client {
            to_server.extend(client.handle(f, now));
        }
    }
    match client.take_result() {
        Some(Ok(data)) => data.len(),
        other => panic!("upload failed: {other:?}"),
    }
}

/// One upload over the virtual bus: the client's frames go through its endpoint, the server
/// answers on its own.
fn upload_bus(
    client: &mut SdoClient,
    server: &mut SdoServer,
    od: &mut Od,
    cep: &mut VirtualEndpoint,
    sep: &mut VirtualEndpoint,
) -> usize {
    let now = Nanos::ZERO;
    for f in client.upload(0x2000, 1, now) {
        cep.send(&f).unwrap();
    }
    loop {
        while let Some(f) = sep.recv(Duration::ZERO).unwrap() {
            for r in server.handle(&f, od, now) {
                sep.send(&r).unwrap();
            }
        }
        let mut any = false;
        while let Some(f) = cep.recv(Duration::ZERO).unwrap() {
            any = true;
            for r in client.handle(&f, now) {
                cep.send(&r).unwrap();
            }
        }
        if let Some(r) = client.take_result() {
            return r.expect("upload").len();
        }
        assert!(any, "stalled");
    }
}

fn bench_sdo(c: &mut Criterion) {
    let data: Vec<u8> = (0..SIZE).map(|i| i as u8).collect();
    let mut g = c.benchmark_group("canopen_sdo_upload_4k");
    g.throughput(Throughput::Bytes(SIZE as u64));
    for (name, mode) in [
        ("segmented", TransferMode::Segmented),
        ("block", TransferMode::Block),
    ] {
        let mut client = SdoClient::new(5);
        client.set_mode(mode);
        let mut server = SdoServer::new(5);
        let mut od = Od(data.clone());
        assert_eq!(upload(&mut client, &mut server, &mut od), SIZE);
        g.bench_function(name, |b| {
            b.iter(|| black_box(upload(&mut client, &mut server, &mut od)))
        });
    }
    g.finish();
    let mut g = c.benchmark_group("canopen_sdo_upload_4k_virtual_bus");
    g.throughput(Throughput::Bytes(SIZE as u64));
    for (name, mode) in [
        ("segmented", TransferMode::Segmented),
        ("block", TransferMode::Block),
    ] {
        let hub = VirtualCan::new();
        let (mut cep, mut sep) = (hub.endpoint(), hub.endpoint());
        let mut client = SdoClient::new(5);
        client.set_mode(mode);
        let mut server = SdoServer::new(5);
        let mut od = Od(data.clone());
        assert_eq!(
            upload_bus(&mut client, &mut server, &mut od, &mut cep, &mut sep),
            SIZE
        );
        g.bench_function(name, |b| {
            b.iter(|| {
                black_box(upload_bus(
                    &mut client,
                    &mut server,
                    &mut od,
                    &mut cep,
                    &mut sep,
                ))
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench_sdo);
criterion_main!(benches);
